//! Integer division for the MCU (the Cortex-M0+ has no divide instruction), small, in place of
//! compiler-builtins' (issue 14: its 32- and 64-bit division took about 1.5 KiB of the 32 KiB).
//!
//! The ARM run-time ABI's entry points LLVM calls: `__aeabi_uidiv`, `__aeabi_uidivmod`,
//! `__aeabi_idiv`, `__aeabi_idivmod` (numerator r0, denominator r1; quotient r0, remainder r1) and
//! `__aeabi_uldivmod`, `__aeabi_ldivmod` (numerator r1:r0, denominator r3:r2; quotient r1:r0,
//! remainder r3:r2). compiler-builtins defines them weak, so these win at link time.
//!
//! Shift and subtract: the denominator is shifted left until it reaches the numerator, then one
//! quotient bit per step, so a division costs about 14 instructions per quotient bit (64-bit
//! operands whose high words are zero take the 32-bit division). Signed
//! division divides the magnitudes and sets the signs as C and Rust do (quotient truncated toward
//! zero, remainder with the numerator's sign). Rust checks division by zero and `MIN / -1` before
//! it calls these; a zero denominator returns a zero quotient and the numerator as remainder.
//!
//! Checked on the linked firmware by `scripts/check-runtime-routines.py` against Python's
//! arithmetic; the step-cost benchmark (`scripts/step-cost.sh`) links them too.

core::arch::global_asm!(
    ".section .text.mmu_uidivmod,\"ax\",%progbits",
    ".global __aeabi_uidiv",
    ".global __aeabi_uidivmod",
    ".type __aeabi_uidiv, %function",
    ".type __aeabi_uidivmod, %function",
    ".thumb_func",
    "__aeabi_uidiv:",
    ".thumb_func",
    "__aeabi_uidivmod:",
    // r0 numerator (becomes the remainder), r1 denominator, r2 quotient, r3 shift count.
    "    movs r2, #0",
    "    movs r3, #0",
    "    cmp r1, #0",
    "    beq 5f",
    "1:  cmp r1, #0", // align: while the top bit is clear and denominator < numerator
    "    blt 2f",
    "    cmp r0, r1",
    "    bls 2f",
    "    lsls r1, r1, #1",
    "    adds r3, #1",
    "    b 1b",
    "2:  adds r2, r2, r2", // shift count + 1 quotient bits
    "    cmp r0, r1",
    "    blo 3f",
    "    subs r0, r0, r1",
    "    adds r2, #1",
    "3:  lsrs r1, r1, #1",
    "    subs r3, #1",
    "    bpl 2b",
    "5:  mov r1, r0",
    "    mov r0, r2",
    "    bx lr",
    ".size __aeabi_uidivmod, . - __aeabi_uidivmod",
    ".section .text.mmu_idivmod,\"ax\",%progbits",
    ".global __aeabi_idiv",
    ".global __aeabi_idivmod",
    ".type __aeabi_idiv, %function",
    ".type __aeabi_idivmod, %function",
    ".thumb_func",
    "__aeabi_idiv:",
    ".thumb_func",
    "__aeabi_idivmod:",
    "    push {{r4, r5, r6, lr}}",
    "    asrs r4, r0, #31", // numerator's sign: 0 or -1
    "    asrs r5, r1, #31",
    "    eors r0, r4", // magnitudes: x ^ s - s
    "    subs r0, r0, r4",
    "    eors r1, r5",
    "    subs r1, r1, r5",
    "    eors r5, r4", // the quotient's sign
    "    bl __aeabi_uidivmod",
    "    eors r0, r5",
    "    subs r0, r0, r5",
    "    eors r1, r4",
    "    subs r1, r1, r4",
    "    pop {{r4, r5, r6, pc}}",
    ".size __aeabi_idivmod, . - __aeabi_idivmod",
    ".section .text.mmu_uldivmod,\"ax\",%progbits",
    ".global __aeabi_uldivmod",
    ".type __aeabi_uldivmod, %function",
    ".thumb_func",
    "__aeabi_uldivmod:",
    // r1:r0 numerator (becomes the remainder), r3:r2 denominator, r5:r4 quotient, r6 shift
    // count, r7 scratch. Five registers pushed and 4 bytes more: the stack stays 8-byte aligned
    // for the call below (AAPCS).
    "    push {{r4, r5, r6, r7, lr}}",
    "    sub sp, #4",
    "    mov r7, r1", // both high words zero: the 32-bit division
    "    orrs r7, r3",
    "    bne 8f",
    "    mov r1, r2",
    "    bl __aeabi_uidivmod",
    "    mov r2, r1",
    "    movs r1, #0",
    "    movs r3, #0",
    "    add sp, #4",
    "    pop {{r4, r5, r6, r7, pc}}",
    "8:  movs r4, #0",
    "    movs r5, #0",
    "    movs r6, #0",
    "    mov r7, r2",
    "    orrs r7, r3",
    "    beq 5f",
    "1:  cmp r3, #0", // align: while the top bit is clear and denominator < numerator
    "    blt 2f",
    "    cmp r1, r3",
    "    bne 6f",
    "    cmp r0, r2",
    "6:  bls 2f",
    "    adds r2, r2, r2",
    "    adcs r3, r3, r3",
    "    adds r6, #1",
    "    b 1b",
    "2:  adds r4, r4, r4", // shift count + 1 quotient bits
    "    adcs r5, r5, r5",
    "    cmp r1, r3",
    "    bne 7f",
    "    cmp r0, r2",
    "7:  blo 3f",
    "    subs r0, r0, r2",
    "    sbcs r1, r1, r3",
    "    adds r4, #1",
    "3:  lsls r7, r3, #31",
    "    lsrs r2, r2, #1",
    "    orrs r2, r7",
    "    lsrs r3, r3, #1",
    "    subs r6, #1",
    "    bpl 2b",
    "5:  mov r2, r0",
    "    mov r3, r1",
    "    mov r0, r4",
    "    mov r1, r5",
    "    add sp, #4",
    "    pop {{r4, r5, r6, r7, pc}}",
    ".size __aeabi_uldivmod, . - __aeabi_uldivmod",
    ".section .text.mmu_ldivmod,\"ax\",%progbits",
    ".global __aeabi_ldivmod",
    ".type __aeabi_ldivmod, %function",
    ".thumb_func",
    "__aeabi_ldivmod:",
    "    push {{r4, r5, r6, lr}}",
    "    asrs r4, r1, #31", // numerator's sign: 0 or -1
    "    asrs r5, r3, #31",
    "    eors r0, r4", // magnitudes: x ^ s - s on both words
    "    eors r1, r4",
    "    subs r0, r0, r4",
    "    sbcs r1, r1, r4",
    "    eors r2, r5",
    "    eors r3, r5",
    "    subs r2, r2, r5",
    "    sbcs r3, r3, r5",
    "    eors r5, r4", // the quotient's sign
    "    bl __aeabi_uldivmod",
    "    eors r0, r5",
    "    eors r1, r5",
    "    subs r0, r0, r5",
    "    sbcs r1, r1, r5",
    "    eors r2, r4",
    "    eors r3, r4",
    "    subs r2, r2, r4",
    "    sbcs r3, r3, r4",
    "    pop {{r4, r5, r6, pc}}",
    ".size __aeabi_ldivmod, . - __aeabi_ldivmod",
);
