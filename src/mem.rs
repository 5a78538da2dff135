//! `memcpy` and `memclr` for the MCU (Cortex-M0+, ARMv6-M), small and fast, in place of
//! compiler-builtins' (issue 14: those took about 1 KiB of the 32 KiB flash).
//!
//! LLVM calls these for struct copies and zeroing: `memcpy` and the ARM run-time ABI's
//! `__aeabi_memcpy`, `__aeabi_memcpy4`, `__aeabi_memcpy8` (dest r0, src r1, length r2; the last two
//! promise word alignment, which these do not need) and `__aeabi_memclr`, `__aeabi_memclr4`,
//! `__aeabi_memclr8` (dest r0, length r1). compiler-builtins defines them weak, so these win at
//! link time. `memcpy` returns the destination (C); the others return nothing. Overlapping ranges
//! are not supported (neither are they by `memcpy`; LLVM calls `memmove` for those).
//!
//! When destination and source share their alignment within a word, bytes are copied up to a word
//! boundary, then two words per `ldm`/`stm`, then the last bytes; otherwise byte by byte (the
//! firmware's copies are almost all of word-aligned structs). Written in assembly: a Rust loop
//! here could be turned back into a call to `memcpy` by LLVM's loop-idiom pass.
//!
//! Checked on the linked firmware by `scripts/check-runtime-routines.py` (every length 0..=40 at
//! every alignment, in the Unicorn emulator, against a reference) from `scripts/firmware-size.sh`;
//! the step-cost benchmark (`scripts/step-cost.sh`) runs the logic with them and compares every byte
//! it sends with the host's.

core::arch::global_asm!(
    ".section .text.mmu_memcpy,\"ax\",%progbits",
    ".global memcpy",
    ".global __aeabi_memcpy",
    ".global __aeabi_memcpy4",
    ".global __aeabi_memcpy8",
    ".type memcpy, %function",
    ".type __aeabi_memcpy, %function",
    ".type __aeabi_memcpy4, %function",
    ".type __aeabi_memcpy8, %function",
    ".thumb_func",
    "memcpy:",
    ".thumb_func",
    "__aeabi_memcpy:",
    ".thumb_func",
    "__aeabi_memcpy4:",
    ".thumb_func",
    "__aeabi_memcpy8:",
    // r0 dest, r1 src, r2 length; r0 is returned, r4 holds the second word, r5 keeps the
    // stack 8-byte aligned.
    "    push {{r0, r4, r5, lr}}",
    "    mov r3, r0",
    "    eors r3, r1",
    "    lsls r3, r3, #30",
    "    bne 5f", // different alignment within a word: bytes only
    "6:  lsls r3, r0, #30",
    "    beq 1f", // dest (and so src) word-aligned
    "    cmp r2, #0",
    "    beq 9f",
    "    ldrb r3, [r1]",
    "    strb r3, [r0]",
    "    adds r1, #1",
    "    adds r0, #1",
    "    subs r2, #1",
    "    b 6b",
    "1:  subs r2, #8", // two words at a time
    "    bcc 3f",
    "    ldm r1!, {{r3, r4}}",
    "    stm r0!, {{r3, r4}}",
    "    b 1b",
    "3:  adds r2, #4", // r2 = length left - 4: one more word if it did not wrap
    "    bcc 7f",
    "    ldm r1!, {{r3}}",
    "    stm r0!, {{r3}}",
    "    b 5f",
    "7:  adds r2, #4",
    "5:  cmp r2, #0", // the last bytes
    "    beq 9f",
    "4:  ldrb r3, [r1]",
    "    strb r3, [r0]",
    "    adds r1, #1",
    "    adds r0, #1",
    "    subs r2, #1",
    "    bne 4b",
    "9:  pop {{r0, r4, r5, pc}}",
    ".size memcpy, . - memcpy",
    ".section .text.mmu_memclr,\"ax\",%progbits",
    ".global __aeabi_memclr",
    ".global __aeabi_memclr4",
    ".global __aeabi_memclr8",
    ".type __aeabi_memclr, %function",
    ".type __aeabi_memclr4, %function",
    ".type __aeabi_memclr8, %function",
    ".thumb_func",
    "__aeabi_memclr:",
    ".thumb_func",
    "__aeabi_memclr4:",
    ".thumb_func",
    "__aeabi_memclr8:",
    // r0 dest, r1 length.
    "    movs r2, #0",
    "6:  lsls r3, r0, #30",
    "    beq 1f",
    "    cmp r1, #0",
    "    beq 9f",
    "    strb r2, [r0]",
    "    adds r0, #1",
    "    subs r1, #1",
    "    b 6b",
    "1:  subs r1, #4", // whole words
    "    bcc 3f",
    "    stm r0!, {{r2}}",
    "    b 1b",
    "3:  adds r1, #4", // the last bytes
    "    beq 9f",
    "4:  strb r2, [r0]",
    "    adds r0, #1",
    "    subs r1, #1",
    "    bne 4b",
    "9:  bx lr",
    ".size __aeabi_memclr, . - __aeabi_memclr",
);
