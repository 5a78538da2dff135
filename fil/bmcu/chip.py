"""The CH32V203C8T6 of the BMCU-C: the core (cpu.py), its memories and the register models,
wired at their addresses (ch32-metapac 0.1.2's ch32v203c8t6 memory map: TIM2-4 0x4000_0000-0800,
IWDG 0x4000_3000, USART3 0x4000_4800, AFIO 0x4001_0000, GPIOA-D 0x4001_0800-1400, ADC1
0x4001_2400, DMA1 0x4002_0000, RCC 0x4002_1000, FLASH 0x4002_2000, EXTEND 0x4002_3800, PFIC
0xE000_E000, SysTick 0xE000_F000), and the scheduler that runs them in virtual time.

Running (as fil/g071/chip.py): the CPU executes in slices that end at the next event (a SysTick
match, a UART character, the watchdog, a flash operation's end), at the end of the request's
time, or after at most SLICE_US; an MMIO write that can change the interrupts or the next event
ends the slice early (`reschedule`; SysTick's writes in native.py). Between slices the models are
brought to the current time, the interrupt lines are sampled into the PFIC, and an interrupt the
core would take is entered. An idle core (the executor found no task to run: executor.py), a
stalled one (a flash operation) or a hung one (`hang`) executes nothing: time jumps to the next
event.

Resets: a system reset (the watchdog, PFIC_CFGR's key) restarts the core and every peripheral,
keeps the SRAM and the flash, and sets RCC_RSTSCKR's flag of the cause plus PINRSTF; a power-on
also clears the SRAM (here: to zero) and sets PORRSTF.

The stack's high-water mark: at each boot the bench paints the RAM between the end of .bss
(`_ebss`) and the stack's top (`_stack_start`, qingke-rt puts the stack at the top of RAM with
nothing below it but .bss) with PAINT, and finds the lowest word no longer PAINT before the next
boot and when asked (`stack_depth`): the deepest the stack has reached, over every boot.
"""

import clock
import executor
from adc import Adc
from as5600 import AngleBuses
from cpu import FLASH_BASE, FLASH_SIZE, RAM_BASE, RAM_SIZE, Cpu, EmulationError  # noqa: F401
from dma1 import Dma1
from flash import Flash, erased_bytes
from gpio import Gpio
from native import NEVER
from pfic import Pfic
from pwm import PwmTimer
from rcc import FLAGS, Afio, Rcc
from regs import Block
from scheduler import Memory, Scheduler, StackPaint, stack_region
from usart import Usart
from watchdog import Watchdog

SYSTICK_IRQ = 12
STIE = 1 << 1
# (base, size) of the MMIO windows the Python models serve (SysTick's is native.py's).
WINDOWS = ((0x4000_0000, 0x2_4000), (0xE000_E000, 0x1000))
PORTS = "ABCD"


class SysTick:
    """The Python side of native.py's SysTick: its next match, its flag and its line."""

    def __init__(self, chip):
        self.chip = chip
        self.native = chip.cpu.native

    def next_event(self):
        nat = self.native
        if not nat.st_read(0, self.chip.time) & STIE:
            return None
        match = nat.st_match()
        return None if match == NEVER else match

    def advance(self, now):
        self.native.st_update(now)

    def irqs(self):
        return (SYSTICK_IRQ,) if self.native.st_irq() else ()


class Chip(Scheduler, StackPaint):
    hz = clock.HZ
    cycles_per_us = clock.CYCLES_PER_US
    clock = clock.CLOCK  # (last: the class body's name `clock` is the module until here)

    def __init__(self, segments, symbols=None):
        symbols = symbols or {}
        image = bytearray(erased_bytes(FLASH_SIZE))
        for address, data in segments:
            if FLASH_BASE <= address < FLASH_BASE + FLASH_SIZE:
                end = address - FLASH_BASE + len(data)
                image[address - FLASH_BASE:end] = data
                if end % 4:  # the programmer pads the image's last word with ones
                    image[end:end + 4 - end % 4] = b"\xff" * (4 - end % 4)
        self.idle = executor.idle_loop(bytes(image), FLASH_BASE, symbols)
        self.cpu = Cpu(self, bytes(image), self.idle)
        self.uc = self.cpu.uc
        self.uc.mem_write(FLASH_BASE, bytes(image))
        self.memory = Memory(self.uc, ((FLASH_BASE, FLASH_SIZE), (RAM_BASE, RAM_SIZE)))
        for base, size in WINDOWS:
            self.uc.mmio_map(base, size, self._mmio_read, base, self._mmio_write, base)
        self.vector_table = symbols.get("_start", FLASH_BASE)
        self.paint = stack_region(symbols)
        self.time = 0
        self.in_slice = False
        self.slice_end = 0
        self.resets = 0
        self.erases_before = self.programs_before = 0
        self.powered = True
        self.hung = False
        self.sensor = {}           # ADC channel -> level, kept across resets
        self.angles = [0x8000] * 4  # each lane's AS5600 sample, kept across resets
        self.flash = None
        self.clock_logged = False
        self.ram = (RAM_BASE, RAM_SIZE)
        self._build(self.reset_flags("power"))
        self.boot()

    # ---- the peripherals ---------------------------------------------------------------------
    def _build(self, flags):
        if self.flash is not None:
            self.erases_before += self.flash.erases
            self.programs_before += self.flash.programs
        self.cpu.native.st_reset()
        self.pfic = Pfic(self)
        self.rcc = Rcc(self, flags)
        self.extend = Block(self)
        self.afio = Afio(self)
        self.flash = Flash(self)
        self.dma = Dma1(self)
        self.tim2, self.tim3, self.tim4 = PwmTimer(self), PwmTimer(self), PwmTimer(self)
        self.usart3 = Usart(self)
        self.adc = Adc(self)
        self.adc.levels = self.sensor
        self.iwdg = Watchdog(self)
        self.gpio = {p: Gpio(self, i) for i, p in enumerate(PORTS)}
        self.buses = AngleBuses(self.gpio)
        for sensor, angle in zip(self.buses.sensors, self.angles):
            sensor.sample = angle
        self.systick = SysTick(self)
        self.blocks = {
            0x4000_0000: self.tim2, 0x4000_0400: self.tim3, 0x4000_0800: self.tim4,
            0x4000_3000: self.iwdg, 0x4000_4800: self.usart3, 0x4001_0000: self.afio,
            0x4001_2400: self.adc, 0x4002_0000: self.dma, 0x4002_1000: self.rcc,
            0x4002_2000: self.flash, 0x4002_3800: self.extend, 0xE000_E000: self.pfic,
        }
        for i, p in enumerate(PORTS):
            self.blocks[0x4001_0800 + 0x400 * i] = self.gpio[p]
        self.timed = [self.systick, self.usart3, self.adc, self.iwdg, self.flash]
        self.irq_sources = [self.systick, self.dma, self.usart3]
        self.others = {}
        self.routes = {}
        self.stall_until = None
        self.reset_request = None

    def set_angle(self, lane, sample):
        self.angles[lane] = sample
        self.buses.sensors[lane].sample = sample

    def _block_at(self, address):
        block, base = self.block_at(0xE000_E000 if address >= 0xE000_E000 else address & ~0x3FF)
        return block, address - base

    def dma_feeders(self, block):
        return (self.usart3.advance, self.adc.advance) if block is self.dma else None

    # ---- time --------------------------------------------------------------------------------
    def reschedule(self, model=None):
        """A model's state may have changed the interrupts or the next event: ends the slice (at
        the next block) if an interrupt is now ready or the model's next event comes before the
        slice's end."""
        if not self.in_slice:
            return
        self.update_irqs()
        cpu = self.cpu
        if cpu.ready_interrupt() is not None:
            cpu.stop_soon()
            return
        if cpu.ready_interrupt(ignore_mie=True) is not None:
            cpu.native.set_irq_ready(1)
        for m in (model,) if model is not None and model in self.timed else self.timed:
            nxt = m.next_event()
            if nxt is not None and nxt < self.slice_end:
                cpu.stop_soon()
                return

    def update_irqs(self):
        pfic = self.pfic
        for m in self.irq_sources:
            for irq in m.irqs():
                if not pfic.active >> irq & 1:
                    pfic.pending |= 1 << irq

    # ---- resets ------------------------------------------------------------------------------
    def reset_flags(self, cause):
        """RSTSCKR's flags after a reset by `cause`: a system reset's keep the last ones, and
        every reset sets PINRSTF (rcc.py)."""
        kept = 0 if cause == "power" else self.rcc.reset_flags()
        return kept | (1 << FLAGS[cause]) | (1 << FLAGS["pin"])

    @property
    def uart(self):
        return self.usart3

    # ---- running (fil/g071/scheduler.py) ------------------------------------------------------
    def before_slice(self):
        self.cpu.native.sync(self.time)  # SysTick's C side counts from here

    def after_slice(self):
        if not self.clock_logged and self.rcc.regs[0x04] >> 2 & 3 == 2:
            self.clock_logged = True
            self.clock_hz = self.rcc.hclk()
