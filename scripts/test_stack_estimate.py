"""Tests of scripts/stack-estimate.py on a small made-up disassembly (no ELF, no llvm-objdump).

    python3 -m unittest scripts/test_stack_estimate.py
"""

import contextlib
import importlib.util
import io
import pathlib
import struct
import subprocess
import sys
import unittest
from unittest import mock

spec = importlib.util.spec_from_file_location(
    "stack_estimate", pathlib.Path(__file__).with_name("stack-estimate.py"))
stack_estimate = importlib.util.module_from_spec(spec)
spec.loader.exec_module(stack_estimate)

# lld pads between functions with 0xd4d4, which decodes as `bmi .-88`: after IRQ's return it
# lands in the reset handler, after asm_fn's (a symbol of size 0) in main.
DISASSEMBLY = """
fake.elf:	file format elf32-littlearm

Disassembly of section .text:

000000c0 <__stext>:
      c0:      	bl	0xd0 <main>             @ imm = #8
      c4:      	udf	#0

000000d0 <main>:
      d0:      	push	{r4, r5, r6, r7, lr}
      d2:      	sub	sp, #400
      d4:      	bl	0x100 <leaf>            @ imm = #40
      d8:      	add	sp, #400
      da:      	pop	{r4, r5, r6, r7, pc}

000000dc <IRQ>:
      dc:      	push	{r7, lr}
      de:      	add	r7, sp, #0
      e0:      	bl	0x100 <leaf>            @ imm = #28
      e4:      	pop	{r7, pc}
      e6:      	bmi	0xc6 <__stext+0x6>      @ imm = #-88

000000e8 <cond>:
      e8:      	push	{r7, lr}
      ea:      	cmp	r0, #0
      ec:      	beq	0xf0 <cond+0x8>         @ imm = #0
      ee:      	pop	{r7, pc}
      f0:      	sub	sp, #8
      f2:      	bl	0x100 <leaf>            @ imm = #10
      f6:      	b	0xee <cond+0x6>         @ imm = #-12

000000f8 <asm_fn>:
      f8:      	push	{lr}
      fa:      	pop	{pc}
      fc:      	bmi	0xd2 <main+0x2>         @ imm = #-88
      fe:      	bmi	0xd2 <main+0x2>         @ imm = #-88

00000100 <leaf>:
     100:      	push	{r7, lr}
     102:      	pop	{r7, pc}

00000104 <table>:
     104:      	push	{r7, lr}
     106:      	add	pc, r0

00000108 <$d>:
     108:	02 00 06 00	.word	0x00060002

0000010c <$t>:
     10c:      	bl	0x100 <leaf>            @ imm = #-16
     110:      	pop	{r7, pc}
     112:      	bl	0xe8 <cond>             @ imm = #-46
     116:      	pop	{r7, pc}

00000118 <IRQ2>:
     118:      	push	{r7, lr}
     11a:      	bl	0xc0 <__stext>          @ imm = #-94
     11e:      	pop	{r7, pc}
"""

SYMBOLS = """
fake.elf:	file format elf32-littlearm

SYMBOL TABLE:
000000c0 l       .text	00000000 $t
00000108 l       .text	00000000 $d
000000c0 g     F .text	00000006 Reset
000000c0 g       .text	00000000 __stext
000000d0 g     F .text	0000000c main
000000dc g     F .text	0000000a IRQ
000000e8 g     F .text	00000010 cond
000000f8 g       .text	00000000 asm_fn
00000100 g     F .text	00000004 leaf
00000104 g     F .text	00000014 table
00000118 g     F .text	00000008 IRQ2
"""

# Initial SP, Reset, NMI, HardFault, 12 system vectors, then IRQ 0 = IRQ, IRQ 1 = IRQ2.
VECTORS = struct.pack("<18I", 0x20001000, 0xC1, *[0] * 14, 0xDD, 0x119)


def objdump(argv, **_):
    text = DISASSEMBLY if "-d" in argv else SYMBOLS
    return subprocess.CompletedProcess(argv, 0, stdout=text, stderr="")


@contextlib.contextmanager
def fake_elf():
    with mock.patch.object(stack_estimate.subprocess, "run", objdump), \
            mock.patch.object(stack_estimate, "sections", lambda elf: [(0, VECTORS)]):
        yield


class StackEstimateTest(unittest.TestCase):
    def graph(self):
        with fake_elf():
            _mem, frame, calls, *_ = stack_estimate.analyse("fake.elf")
        return frame, calls

    def test_padding_after_a_return_is_not_a_branch(self):
        frame, calls = self.graph()
        self.assertEqual(calls["IRQ"], {"leaf"})
        self.assertEqual(calls["asm_fn"], set())
        self.assertEqual(frame["asm_fn"], 4)

    def test_interrupt_path_does_not_include_the_thread_path(self):
        frame, calls = self.graph()
        depth = stack_estimate.deepest("IRQ", frame, calls, {}, set(), set())
        self.assertEqual(depth[:2], (16, ["IRQ", "leaf"]))

    def test_code_after_a_return_reached_by_a_branch_counts(self):
        frame, calls = self.graph()
        self.assertEqual(frame["cond"], 16)
        self.assertEqual(calls["cond"], {"leaf"})

    def test_jump_table_targets_count(self):
        frame, calls = self.graph()
        self.assertEqual(calls["table"], {"leaf", "cond"})
        self.assertEqual(frame["table"], 8)

    def test_worst_case(self):
        out = io.StringIO()
        with fake_elf(), mock.patch.object(sys, "argv", ["stack-estimate.py", "fake.elf",
                                                         "--vector-table", "0"]), \
                contextlib.redirect_stdout(out):
            stack_estimate.main()
        # thread: __stext 0 + main 420 + leaf 8; IRQ 8 + leaf 8; two exception frames 72. IRQ2's
        # call of the reset handler is not followed (nothing calls it) but reported.
        self.assertIn("worst-case stack: 516 B", out.getvalue())
        self.assertIn("branches into the reset handler ignored, from: IRQ2", out.getvalue())


if __name__ == "__main__":
    unittest.main()
