"""Virtual time of the emulated chip: one integer count of 64 MHz system-clock cycles since the
bench started. Everything derives from it deterministically (never from the wall clock).

The CPU's instructions advance it by a fixed cost: the Cortex-M0+ at 64 MHz with 2 flash wait
states averages about 2.45 cycles per instruction on this firmware (docs/firmware-in-the-loop.md),
taken here as 5/2 cycles per instruction. Sleep (WFE/WFI), a flash erase's stall and `hang` advance
it to the next peripheral event without executing anything.
"""

import linebench

HZ = 64_000_000
CYCLES_PER_US = 64
# Cycles per instruction as a fraction (5/2 = 2.5).
CPI_NUM, CPI_DEN = 5, 2
# 115200 baud, 8N1: 10 bits per character. Fractional cycles kept exact by computing arrival
# times from a character index (see usart.py).
BAUD = 115_200
BITS_PER_CHAR = 10
CLOCK = linebench.Clock(HZ, CPI_NUM, CPI_DEN, BAUD, BITS_PER_CHAR)
us, instructions_to_cycles, cycles_to_instructions, char_time = (
    CLOCK.us, CLOCK.instructions_to_cycles, CLOCK.cycles_to_instructions, CLOCK.char_time)
