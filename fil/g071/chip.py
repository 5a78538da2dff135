"""The STM32G071RB: the core (cpu.py), its memories and the register models, wired at their
addresses (RM0444 §2.2.2, memory map), and the scheduler that runs them in virtual time.

Running: the CPU executes in slices that end at the next peripheral event (a timer compare, a
UART character, an ADC conversion, the watchdog, a flash operation's end), at the end of the
request's time, or after at most SLICE_US; an MMIO write that can change the interrupts or the
next event stops the slice early (`reschedule`). Between slices the models are brought to the
current time, the interrupt lines are sampled into the NVIC, and a pending interrupt is taken.
A sleeping core (WFE/WFI), a stalled one (flash busy) or a hung one (`hang`) executes nothing:
time jumps to the next event.

The stack's high-water mark: the chip paints the RAM between `__sheap` and `_stack_start` at
each boot (fil/g071/scheduler.py StackPaint) when the bench names the region.

Resets (RM0444 §5.1): a system reset (watchdog, SYSRESETREQ) restarts the core and every
peripheral, keeps the SRAM and the flash, and sets the reset flags in RCC_CSR (plus PINRSTF, the
internal reset drives NRST); a power-on reset also clears the SRAM (here: to zero) and sets
PWRRSTF.
"""

import unicorn

import clock
from adc import Adc
from cpu import Cpu, EmulationError, FLASH_BASE, FLASH_SIZE, RAM_BASE, RAM_SIZE
from crc import Crc
from dma import Dma, DmaMux
from flash import Flash
from gpio import Gpio
from iwdg import Iwdg
from nvic import Scs
from rcc import CSR_FLAGS, Pwr, Rcc
from regs import Block
from scheduler import Memory, Scheduler, StackPaint
from timers import Timer
from usart import Usart

# (base, size) of the MMIO windows Unicorn maps to the models.
WINDOWS = ((0x4000_0000, 0x1_6000), (0x4002_0000, 0x6400), (0x5000_0000, 0x1800),
           (0xE000_E000, 0x1000))


class Chip(Scheduler, StackPaint):
    clock = clock.CLOCK

    def __init__(self, segments, paint=None):
        image = bytearray(b"\xff" * FLASH_SIZE)
        for address, data in segments:
            if FLASH_BASE <= address < FLASH_BASE + FLASH_SIZE:
                image[address - FLASH_BASE:address - FLASH_BASE + len(data)] = data
        self.cpu = Cpu(self, bytes(image), segments)
        self.uc = self.cpu.uc
        self.uc.mem_write(FLASH_BASE, bytes(image))
        self.memory = Memory(self.uc, ((FLASH_BASE, FLASH_SIZE), (RAM_BASE, RAM_SIZE)))
        for base, size in WINDOWS:
            self.uc.mmio_map(base, size, self._mmio_read, base, self._mmio_write, base)
        self.time = 0
        self.in_slice = False
        self.slice_end = 0
        self.resets = 0
        self.erases_before = 0     # counts of flash models replaced by resets
        self.programs_before = 0
        self.powered = True
        self.hung = False
        self.sensor = {}           # ADC channel -> level, kept across resets
        self.encoder = {}          # encoder timer's name -> the lane's count, kept across resets
        self.flash = None
        self.paint = paint         # the stack's region, painted at each boot (StackPaint)
        self.ram = (RAM_BASE, RAM_SIZE)
        self._build(self.reset_flags("power"))
        self.boot()

    # ---- the peripherals ---------------------------------------------------------------------
    def _build(self, csr_flags):
        if self.flash is not None:
            self.erases_before += self.flash.erases
            self.programs_before += self.flash.programs
        self.scs = Scs(self)
        self.rcc = Rcc(self, csr_flags)
        self.pwr = Pwr(self)
        self.flash = Flash(self)
        self.dma = Dma(self)
        self.dmamux = DmaMux(self, self.dma)
        self.tim2 = Timer(self, irq=15, bits=32)
        self.tim3 = Timer(self, irq=16)
        # The `g071-n20` build's: TIM1 (an encoder), TIM14/16/17 (PWM), TIM15 (embassy-time).
        self.tim1 = Timer(self)
        self.tim14 = Timer(self)
        self.tim15 = Timer(self, irq=20)
        self.tim16 = Timer(self)
        self.tim17 = Timer(self)
        for name, count in self.encoder.items():
            getattr(self, name).encoder_count = count
        self.usart1 = Usart(self)
        self.adc = Adc(self)
        self.adc.levels = self.sensor
        self.iwdg = Iwdg(self)
        self.crc = Crc(self)
        self.gpio = [Gpio(self, port) for port in range(6)]
        self.blocks = {
            0x4000_0000: self.tim2, 0x4000_0400: self.tim3, 0x4000_2000: self.tim14,
            0x4001_2C00: self.tim1, 0x4001_4000: self.tim15, 0x4001_4400: self.tim16,
            0x4001_4800: self.tim17, 0x4000_3000: self.iwdg,
            0x4000_7000: self.pwr, 0x4001_2400: self.adc, 0x4001_3800: self.usart1,
            0x4002_0000: self.dma, 0x4002_0800: self.dmamux, 0x4002_1000: self.rcc,
            0x4002_2000: self.flash, 0x4002_3000: self.crc,
        }
        for port, g in enumerate(self.gpio):
            self.blocks[0x5000_0000 + 0x400 * port] = g
        self.timed = [self.tim2, self.tim3, self.tim15, self.usart1, self.adc, self.iwdg, self.flash]
        self.irq_sources = [self.tim2, self.tim3, self.tim15, self.usart1, self.adc, self.dma, self.flash]
        self.others = {}  # plain storage for every other register block touched
        self.routes = {}
        self.stall_until = None
        self.reset_request = None

    def set_encoder(self, timer, count):
        """The lane's encoder count at the inputs of `timer` (a name: "tim1", "tim2", "tim3")."""
        self.encoder[timer] = count
        getattr(self, timer).encoder_count = count

    def _block_at(self, address):
        if address >= 0xE000_E000:
            return self.scs, address - 0xE000_E000
        if 0x4001_2400 <= address < 0x4001_2800:  # the ADC's common registers at +0x300
            return self.adc, address - 0x4001_2400
        block, base = self.block_at(address & ~0x3FF)
        return block, address - base

    def dma_feeders(self, block):
        if block is self.dma or block is self.dmamux:
            return (self.usart1.advance, self.adc.advance)
        return None

    # ---- time --------------------------------------------------------------------------------
    def reschedule(self, model=None):
        """Called by a model whose state may have changed the interrupts or the next event:
        ends the slice (at the next block) if an interrupt is now ready to be taken or the
        model's next event (for the DMA: its producers') comes before the slice's end. A line
        that became pending while PRIMASK masks it arms the CPSIE hook instead."""
        if not self.in_slice:
            return
        if model is self.dma:
            models, lines = (self.usart1, self.adc), (self.dma, self.usart1, self.adc)
        elif model is not None:
            models = lines = (model,)
        else:
            models, lines = self.timed, self.irq_sources
        active = self.cpu.active
        scs = self.scs
        before = scs.pending
        for m in lines:
            for irq in m.irqs():
                if 16 + irq not in active:
                    scs.pending |= 1 << irq
        if model is None or (scs.pending & ~before & scs.enabled):
            if self.cpu.ready_interrupt() is not None:
                self.cpu.stop_soon()
                return
            if self.cpu.ready_interrupt(ignore_primask=True) is not None:
                self.cpu.native.set_irq_ready(1)
        for m in models:
            nxt = m.next_event()
            if nxt is not None and nxt < self.slice_end:
                self.cpu.stop_soon()
                return

    def update_irqs(self):
        scs = self.scs
        active = set(v - 16 for v in self.cpu.active)
        for m in self.irq_sources:
            for irq in m.irqs():
                if irq not in active:
                    scs.pending |= 1 << irq

    # ---- resets ------------------------------------------------------------------------------
    def reset_flags(self, cause):
        """RCC_CSR's flags after a reset by `cause`: a system reset's keep the last ones, and
        every reset sets PINRSTF (RM0444 §5.1.2)."""
        kept = 0 if cause == "power" else self.rcc.reset_flags()
        return kept | (1 << CSR_FLAGS[cause]) | (1 << CSR_FLAGS["pin"])

    @property
    def uart(self):
        return self.usart1
