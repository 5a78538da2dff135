"""What the Unicorn benches' chips share, whatever the core (fil/g071/chip.py, fil/bmcu/chip.py):
the scheduler that runs the CPU in slices between the peripherals' events in virtual time, the
stall of a flash operation, the requested reset, the flash operations' counts, and the core's
capture of CPU stores into the flash (`FlashStores`).

A chip (`Scheduler`) maps its MMIO windows to `_mmio_read`/`_mmio_write`, gives `_block_at(address)
-> (block, offset)` and `dma_feeders(block)` (for a DMA block, the `advance` of the peripherals
that feed it, else None), and sets `routes` ({}), `cpu` (with `native.count()`, `executed()`, `stop_soon()`,
`ready_interrupt()`, `take_interrupt(n)`, `sleeping`, `wakes()`, `run(instructions)`), `clock`
(a linebench.Clock), `timed` (models with `next_event()` and `advance(now)`), `flash`, `time`,
`in_slice`, `slice_end`, `stall_until`, `reset_request`, `powered`, `hung`, `erases_before`,
`programs_before`, `ram` ((base, size)), `uart` (the printer UART's model), and gives `_build(flags)`,
`reset_flags(cause)` and `update_irqs()`. It may override
`before_slice()` and `after_slice()`.
"""

from regs import Block

SLICE_US = 200
# What the RAM between the static data and the stack's top holds at each boot (StackPaint).
PAINT = 0xDEAD_BEEF


def stack_region(symbols):
    """(start, top) of the RAM the stack can grow into, from the image's symbols: from the end of
    the static data (`__sheap` for cortex-m-rt, `_ebss` for qingke-rt) to the stack's top
    (`_stack_start`, both put the stack at the top of RAM with nothing below it), or None."""
    start = next((symbols[n] for n in ("__sheap", "_ebss", "__ebss") if n in symbols), None)
    top = symbols.get("_stack_start")
    return (start, top) if start is not None and top is not None and start < top else None


class StackPaint:
    """The stack's high-water mark: at each boot the chip paints `paint` ((start, top) or None)
    with PAINT, and the lowest word no longer PAINT before the next boot or when asked is the
    deepest the stack has reached, over every boot (`deepest`, bytes below the top). The chip sets
    `paint`, `uc` and `powered`, calls `paint_stack()` at each boot before the core starts and
    `forget_stack()` when the power goes."""

    deepest = 0
    painted = False

    def paint_stack(self):
        self.measure_stack()
        if self.paint:
            start, top = self.paint
            self.uc.mem_write(start, PAINT.to_bytes(4, "little") * ((top - start) // 4))
            self.painted = True

    def forget_stack(self):
        self.measure_stack()
        self.painted = False

    def measure_stack(self):
        """The deepest the stack has reached below its top, bytes, over every boot so far."""
        if not self.paint or not self.powered or not self.painted:
            return self.deepest
        start, top = self.paint
        data = bytes(self.uc.mem_read(start, top - start))
        pattern = PAINT.to_bytes(4, "little")
        for i in range(0, len(data), 4):
            if data[i:i + 4] != pattern:
                self.deepest = max(self.deepest, top - (start + i))
                break
        return self.deepest


class Memory:
    """Flash and SRAM as the DMA and the flash controller see them (not through the MMIO):
    `regions` is ((base, size), ...); an access outside them raises MemoryError."""

    def __init__(self, uc, regions):
        self.uc = uc
        self.regions = regions

    def _check(self, address, n):
        if not any(base <= address and address + n <= base + size for base, size in self.regions):
            raise MemoryError(hex(address))

    def read(self, address, n):
        self._check(address, n)
        return bytes(self.uc.mem_read(address, n))

    def write(self, address, data):
        self._check(address, len(data))
        self.uc.mem_write(address, bytes(data))


class Scheduler:
    # ---- MMIO ----------------------------------------------------------------------------------
    def block_at(self, base):
        """The block at `base` (a 1 KiB boundary): a model, or plain storage made on first use
        (unknown peripherals read back what was written)."""
        block = self.blocks.get(base)
        if block is None:
            block = self.others.get(base)
            if block is None:
                block = self.others[base] = Block(self)
        return block, base

    def _route(self, address):
        """(block, offset, what to bring up to date) for an MMIO address, cached per address.
        For a DMA block that is the peripherals that feed it (its counters and the memory it
        wrote must be current), for the others the block itself if it has events."""
        route = self.routes.get(address)
        if route is None:
            block, off = self._block_at(address)
            bring = self.dma_feeders(block)
            if bring is None:
                bring = (block.advance,) if type(block).advance is not Block.advance else ()
            route = self.routes[address] = (block, off, bring)
        return route

    def _brought(self, address):
        """The block and offset at `address`, brought up to now first (the DMA feeders of the
        block, or its own `advance`)."""
        block, off, bring = self.routes.get(address) or self._route(address)
        if bring:
            now = self.now()
            for advance in bring:
                advance(now)
        return block, off

    def _mmio_read(self, uc, offset, size, base):
        block, off = self._brought(base + offset)
        if size == 4:
            return block.read_reg(off)
        return block.read(off, size)

    def _mmio_write(self, uc, offset, size, value, base):
        block, off = self._brought(base + offset)
        if size == 4:
            block.write_reg(off, value, 0xFFFF_FFFF)
        else:
            block.write(off, size, value)

    # ---- time ----------------------------------------------------------------------------------
    def now(self):
        if self.in_slice:
            return self.time + self.clock.instructions_to_cycles(self.cpu.executed())
        return self.time

    def stall(self, until):
        """A flash operation stalls the CPU until `until` (the models go on)."""
        self.stall_until = until
        if self.in_slice:
            self.cpu.stop_soon()

    def request_reset(self, cause):
        self.reset_request = cause
        if self.in_slice:
            self.cpu.stop_soon()

    def next_event(self):
        times = [t for t in (m.next_event() for m in self.timed) if t is not None]
        return min(times) if times else None

    def advance_models(self, now):
        for m in self.timed:
            m.advance(now)

    def erases(self):
        return self.erases_before + self.flash.erases

    def programs(self):
        return self.programs_before + self.flash.programs

    # ---- resets ------------------------------------------------------------------------------
    def system_reset(self, cause):
        """A system reset (the watchdog, a software reset): every model anew with the reset flags
        of `cause` (`reset_flags(cause)`), SRAM and flash kept; what left the UART's pin before
        it is still the step's TX."""
        sent = self.uart.sent
        self._build(self.reset_flags(cause))
        self.uart.sent = sent
        self.resets += 1
        self.hung = False
        self.boot()

    def power_off(self):
        self.forget_stack()
        self.flash.power_loss()
        self.powered = False

    def power_on(self):
        """A power-on reset: the SRAM cleared (`ram`: (base, size)), the power-on flags
        (`reset_flags("power")`)."""
        base, size = self.ram
        self.uc.mem_write(base, bytes(size))
        self._build(self.reset_flags("power"))
        self.resets += 1
        self.powered = True
        self.hung = False
        self.boot()

    def boot(self):
        """The core starts from its reset vector, the stack's region freshly painted."""
        self.paint_stack()
        self.cpu.reset()

    def before_slice(self):
        """Called as each round of the loop starts, at `time`."""

    def after_slice(self):
        """Called after each slice the CPU ran."""

    def run_until(self, end):
        """Runs the chip to `end` (cycles): the models at their events, the CPU in slices (a
        stalled, hung or sleeping CPU executes nothing: time jumps to the next event), the
        interrupts taken between slices, a requested reset carried out."""
        cpu = self.cpu
        clock = self.clock
        while self.time < end:
            self.before_slice()
            self.advance_models(self.time)
            if self.reset_request:
                cause, self.reset_request = self.reset_request, None
                self.system_reset(cause)
                continue
            if not self.powered:
                self.time = end
                break
            self.update_irqs()
            nxt = self.next_event()
            limit = end if nxt is None else min(end, max(nxt, self.time + 1))
            if self.stall_until is not None:
                if self.stall_until > self.time:
                    self.time = min(limit, self.stall_until)
                    continue
                self.stall_until = None
            if self.hung:
                self.time = limit
                continue
            if cpu.sleeping:
                if not cpu.wakes():
                    self.time = limit
                    continue
                cpu.sleeping = False
            irq = cpu.ready_interrupt()
            if irq is not None:
                cpu.take_interrupt(irq)
            limit = min(limit, self.time + clock.us(SLICE_US))
            self.slice_end = limit
            self.in_slice = True
            try:
                executed = cpu.run(clock.cycles_to_instructions(limit - self.time))
            finally:
                self.in_slice = False
            self.time += clock.instructions_to_cycles(executed)
            self.after_slice()


class FlashStores:
    """A core's running (`_emulate`, `executed`, `stop_soon`) and its CPU stores into its flash: they go to the flash controller's model (`chip.flash
    .store`), and the memory Unicorn wrote at once gets its old bytes back when the slice ends
    (the controller changes the array when its operation completes, after the stall). The core
    sets `chip`, `uc` and `native`, hooks `_on_flash_write` on its flash's range and calls
    `_apply_flash_writes` after each `emu_start`."""

    def _on_flash_write(self, uc, access, address, size, value, _):
        self.flash_writes.append((address, bytes(uc.mem_read(address, size))))
        self.chip.flash.store(address, size, value & ((1 << (8 * size)) - 1))
        self.stop_soon()

    def _apply_flash_writes(self):
        writes, self.flash_writes = self.flash_writes, []
        for address, old in reversed(writes):
            self.uc.mem_write(address, old)

    def executed(self):
        return self.native.count() - self.count_base

    def _emulate(self, instructions, begin, until, irq_ready):
        """Runs Unicorn from `begin` for up to `instructions` (block granular: the native
        counter stops it), telling the native hooks whether an interrupt is ready."""
        nat = self.native
        self.count_base = nat.count()
        nat.set_irq_ready(1 if irq_ready else 0)
        nat.set_limit(self.count_base + instructions)
        self.uc.emu_start(begin, until)

    def stop_soon(self):
        """Ends the slice at the next block boundary. (uc.emu_stop from an MMIO or memory
        callback leaves PC on the accessing instruction, which would then run twice.)"""
        self.native.set_limit(self.native.count())
