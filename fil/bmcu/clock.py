"""Virtual time of the emulated CH32V203: one integer count of 120 MHz HCLK cycles since the
bench started, from which everything derives deterministically (never from the wall clock).

The image runs at 120 MHz (src/board/bmcu/clock.rs: HSI x 15 through the PLL; not the chip's 144
MHz, where WCH's flash example wants HCLK halved around every flash write); the bench counts
at 120 MHz from the start, also before the PLL is on (the RCC model computes the clock the image
chose and the bench logs it, rcc.py). An instruction advances time by 3/2 cycles: an
assumption. The QingKe V4B is a 3-stage pipeline with static branch prediction, single-cycle
multiplication and zero-wait flash at 144 MHz (CH32V203 datasheet V2.6, overview); what it
averages on this firmware was not found measured anywhere: loads, stores and taken branches are
taken to cost about one cycle more each, half the instructions of this code. The busy
percentage of the real-time contract takes the same 3/2 (`CONTRACT_CPI`): the image's AS5600
driver busy-waits on SysTick's count, so much of what it executes is time-bound, and a higher
figure for the contract alone would count those waits longer than the time they last. Sleep (the idle executor), a flash operation's stall and `hang` advance time
to the next event without executing anything.
"""

import linebench  # fil/g071/linebench.py

HZ = 120_000_000
CYCLES_PER_US = HZ // 1_000_000
# Cycles per instruction as a fraction (3/2), and the contract's figure.
CPI_NUM, CPI_DEN = 3, 2
CONTRACT_CPI = CPI_NUM / CPI_DEN
# The printer's line: 115200 baud, 8N1, 10 bits a character (fil/PROTOCOL.md).
BAUD = 115_200
BITS_PER_CHAR = 10
CLOCK = linebench.Clock(HZ, CPI_NUM, CPI_DEN, BAUD, BITS_PER_CHAR)
us, instructions_to_cycles, cycles_to_instructions, char_time = (
    CLOCK.us, CLOCK.instructions_to_cycles, CLOCK.cycles_to_instructions, CLOCK.char_time)
