"""The BMCU-C bench's C: the instruction counter, the QingKe CSRs Unicorn lacks, the stops the
Python core needs (mret, an idle executor, a trap), and SysTick, compiled once with the system's
C compiler and called from Unicorn's C side.

Why C: the image's critical sections (every embassy-sync access, the executor's run queue) read
and write the WCH CSR 0x800, which Unicorn 2.1.4 raises as an illegal instruction, and its
bit-banged I2C waits poll SysTick's counter: thousands of each a virtual millisecond, which a
Python callback each would run at a tenth of real time. Python runs at the other MMIO accesses
and between slices (fil/g071/native.py, the same reasoning).

- Block hook: adds the block's instruction count (RISC-V: an instruction is 4 bytes when its low
  two bits are 11, else 2) to a 64-bit counter, the bench's clock, and stops once the counter
  reaches the slice's limit. An instruction that traps in the middle of a block ends it: the
  instructions after it, counted at the block's entry, are taken back (`uncount`).
- Interrupt hook (Unicorn calls it for every synchronous exception; for an illegal instruction
  with the PC already past it, so execution resumes after it when the hook returns):
  - CSRRW/CSRRS/CSRRC and their immediate forms on 0x800 (gintenr: bits 3 and 7 are mstatus's
    MIE and MPIE, QingKe V4's alias, which qingke's critical section uses with the mask 0x88;
    qingke 0.8.3 src/register/gintenr.rs, src/critical_section_impl.rs), on 0x804 (intsyscr),
    0xBC0 (corecfgr) and 0xBC1 (inestcr), plain storage: emulated here. Setting MIE through
    0x800 while the bench has an interrupt ready stops the slice (`STOP_ENABLE`), so that the
    interrupt is taken at once, as on the chip.
  - Any other exception (a real illegal instruction, ecall, ebreak, a misaligned access) stops
    with `STOP_EXCEPTION`, its cause and PC kept: the Python core takes the trap (vector 3).
- Code hooks: on every `mret` (stop before it: the Python core returns from the interrupt with
  the hardware prologue's registers, cpu.py), `wfi` (stop), and on the spinning executor's poll
  loop head (`idle_pc`): when the run queue's head (the word at register `idle_reg` plus
  `idle_off`) is null and mstatus.MIE is set, nothing can change until an interrupt, so the
  core stops (`STOP_IDLE`) and the bench skips to the next event (chip.py).
- SysTick (0xE000F000, mapped as C MMIO callbacks): CTLR (STE 0, STIE 1, STCLK 2, STRE 3,
  MODE 4, INIT 5), SR (CNTIF 0, write 0 to clear), CNTL/CNTH (0x08/0x0C), CMPL/CMPH
  (0x10/0x14); register layout from ch32-metapac 0.1.2 `systick_rv4` (WCH's SVD). The 64-bit
  counter counts HCLK/8 (STCLK 0) or HCLK (STCLK 1) from the virtual time, up (MODE 0) or down
  (MODE 1); with STRE an up-count restarts at 0 after reaching CMP. CNTIF is set when the count
  reaches CMP (up) and raises core interrupt 12 with STIE. INIT reloads the counter (0 up, CMP
  down). A write stops the slice so that the bench plans the next match again.
  Left out: SWIE (the software interrupt, bit 31), STRE in down-count mode.
"""

import ctypes
import functools

import cbuild

SOURCE = r"""
#include <stdint.h>
#include <stdlib.h>
typedef int (*stop_fn)(void *);
typedef int (*reg_fn)(void *, int, void *);
typedef int (*mem_fn)(void *, uint64_t, void *, uint64_t);
static stop_fn uc_stop;
static reg_fn uc_reg_read, uc_reg_write;
static mem_fn uc_mem_read;
void nat_set_api(stop_fn s, reg_fn r, reg_fn w, mem_fn m) {
    uc_stop = s; uc_reg_read = r; uc_reg_write = w; uc_mem_read = m;
}
#define REG_X0 1
#define REG_MSTATUS 116
#define REG_PC 190
enum { STOP_NONE, STOP_LIMIT, STOP_MRET, STOP_IDLE, STOP_EXCEPTION, STOP_ENABLE, STOP_WFI };
struct nat {
    const uint8_t *image; uint64_t base, length;
    uint64_t count, limit; int stopped_by;
    uint64_t blk_start; uint32_t blk_size;
    uint32_t exc_cause, exc_pc;
    uint64_t time0, count0, cpi_num, cpi_den;
    int irq_ready;
    uint32_t csr[4];                    /* 0x804, 0xBC0, 0xBC1, spare */
    uint64_t idle_pc; int idle_reg; int32_t idle_off; uint64_t idles, csr_traps;
    uint32_t st_ctlr, st_sr; uint64_t st_cnt0, st_t0, st_cmp, st_last; int st_changed;
};
struct nat *nat_new(const uint8_t *img, uint64_t b, uint64_t len, uint64_t num, uint64_t den) {
    struct nat *n = calloc(1, sizeof *n);
    if (n) { n->image = img; n->base = b; n->length = len; n->limit = ~0ULL;
             n->cpi_num = num; n->cpi_den = den; n->idle_pc = ~0ULL; }
    return n;
}
void nat_free(struct nat *n) { free(n); }
uint64_t nat_count(struct nat *n) { return n->count; }
void nat_set_limit(struct nat *n, uint64_t l) { n->limit = l; n->stopped_by = 0; }
int nat_stopped_by(struct nat *n) { return n->stopped_by; }
uint32_t nat_exc_cause(struct nat *n) { return n->exc_cause; }
uint32_t nat_exc_pc(struct nat *n) { return n->exc_pc; }
void nat_set_irq_ready(struct nat *n, int r) { n->irq_ready = r; }
void nat_sync(struct nat *n, uint64_t time) { n->time0 = time; n->count0 = n->count; }
uint64_t nat_now(struct nat *n) { return n->time0 + (n->count - n->count0) * n->cpi_num / n->cpi_den; }
void nat_set_idle(struct nat *n, uint64_t pc, int reg, int32_t off) { n->idle_pc = pc; n->idle_reg = reg; n->idle_off = off; }
uint64_t nat_idles(struct nat *n) { return n->idles; }
uint64_t nat_csr_traps(struct nat *n) { return n->csr_traps; }
uint32_t nat_csr(struct nat *n, int i) { return n->csr[i]; }
void nat_reset_core(struct nat *n) { n->csr[0] = n->csr[1] = n->csr[2] = n->csr[3] = 0; }

static uint32_t instructions(struct nat *n, uint64_t address, uint64_t size) {
    uint64_t off = address - n->base, i = 0; uint32_t k = 0;
    if (address < n->base || off + size > n->length) return (uint32_t)(size / 4 ? size / 4 : 1);
    while (i < size) { i += (n->image[off + i] & 3) == 3 ? 4 : 2; k++; }
    return k;
}
/* Takes back the instructions of the current block from `pc` on: counted, never executed. */
static void uncount(struct nat *n, uint64_t pc) {
    uint64_t end = n->blk_start + n->blk_size;
    if (pc >= n->blk_start && pc < end) n->count -= instructions(n, pc, end - pc);
}
void nat_block(void *uc, uint64_t address, uint32_t size, void *user) {
    struct nat *n = user;
    n->count += instructions(n, address, size);
    n->blk_start = address; n->blk_size = size;
    if (n->count >= n->limit && !n->stopped_by) { n->stopped_by = STOP_LIMIT; uc_stop(uc); }
}
static uint32_t *custom_csr(struct nat *n, uint32_t csr) {
    switch (csr) { case 0x804: return &n->csr[0]; case 0xBC0: return &n->csr[1]; case 0xBC1: return &n->csr[2]; }
    return 0;
}
static uint32_t fetch32(struct nat *n, void *uc, uint64_t address) {
    uint64_t off = address - n->base; uint32_t w = 0;
    if (address >= n->base && off + 4 <= n->length)
        return n->image[off] | n->image[off + 1] << 8 | n->image[off + 2] << 16 | (uint32_t)n->image[off + 3] << 24;
    uc_mem_read(uc, address, &w, 4);
    return w;
}
void nat_intr(void *uc, uint32_t intno, void *user) {
    struct nat *n = user;
    uint32_t pc = 0;
    uc_reg_read(uc, REG_PC, &pc);
    if (intno == 2 && pc >= 4) {
        uint32_t insn = fetch32(n, uc, pc - 4), f3 = (insn >> 12) & 7;
        uint32_t csr = insn >> 20, rd = (insn >> 7) & 31, rs1 = (insn >> 15) & 31;
        uint32_t *slot = custom_csr(n, csr);
        if ((insn & 0x7f) == 0x73 && f3 && f3 != 4 && (csr == 0x800 || slot)) {
            uint32_t src = rs1, old, mst = 0, now;
            if (!(f3 & 4)) { src = 0; if (rs1) uc_reg_read(uc, REG_X0 + rs1, &src); }
            if (csr == 0x800) { uc_reg_read(uc, REG_MSTATUS, &mst); old = mst & 0x88; } else old = *slot;
            now = old;
            switch (f3 & 3) { case 1: now = src; break; case 2: now = old | src; break; case 3: now = old & ~src; break; }
            if (rd) uc_reg_write(uc, REG_X0 + rd, &old);
            if ((f3 & 3) == 1 || rs1) {
                if (csr == 0x800) {
                    uint32_t m2 = (mst & ~0x88u) | (now & 0x88u);
                    uc_reg_write(uc, REG_MSTATUS, &m2);
                    if (!(mst & 8) && (m2 & 8) && n->irq_ready && !n->stopped_by) { n->stopped_by = STOP_ENABLE; uc_stop(uc); }
                } else *slot = now;
            }
            n->csr_traps++;
            uncount(n, pc);
            return;
        }
    }
    n->exc_cause = intno; n->exc_pc = pc;
    n->stopped_by = STOP_EXCEPTION;
    uncount(n, pc);
    uc_stop(uc);
}
void nat_mret(void *uc, uint64_t address, uint32_t size, void *user) {
    struct nat *n = user; (void)address; (void)size;
    n->stopped_by = STOP_MRET; uc_stop(uc);
}
void nat_wfi(void *uc, uint64_t address, uint32_t size, void *user) {
    struct nat *n = user; (void)size;
    n->stopped_by = STOP_WFI; uncount(n, address + 4); uc_stop(uc);
}
void nat_idle(void *uc, uint64_t address, uint32_t size, void *user) {
    struct nat *n = user; uint32_t base = 0, head = 1, mst = 0; (void)size;
    if (address != n->idle_pc) return;
    uc_reg_read(uc, REG_X0 + n->idle_reg, &base);
    if (uc_mem_read(uc, (uint32_t)(base + n->idle_off), &head, 4) != 0) return;
    uc_reg_read(uc, REG_MSTATUS, &mst);
    if (head == 0 && (mst & 8) && !n->stopped_by) {
        n->idles++; n->stopped_by = STOP_IDLE; uncount(n, address); uc_stop(uc);
    }
}

/* ---- SysTick ---- */
static uint64_t st_div(struct nat *n) { return (n->st_ctlr & 4) ? 1 : 8; }
static uint64_t st_ticks(struct nat *n, uint64_t now) { return now > n->st_t0 ? (now - n->st_t0) / st_div(n) : 0; }
uint64_t nat_st_count(struct nat *n, uint64_t now) {
    uint64_t t;
    if (!(n->st_ctlr & 1)) return n->st_cnt0;
    t = st_ticks(n, now);
    if (n->st_ctlr & 0x10) return n->st_cnt0 - t;
    if ((n->st_ctlr & 8) && n->st_cmp) return (n->st_cnt0 + t) % (n->st_cmp + 1);
    return n->st_cnt0 + t;
}
/* The cycle of the first match after st_last, or ~0. */
uint64_t nat_st_match(struct nat *n) {
    uint64_t k, last, div = st_div(n);
    if (!(n->st_ctlr & 1)) return ~0ULL;
    last = st_ticks(n, n->st_last);
    if (n->st_ctlr & 0x10) {
        if (n->st_cnt0 <= last) return ~0ULL;
        k = n->st_cnt0;
    } else if ((n->st_ctlr & 8) && n->st_cmp) {
        uint64_t p = n->st_cmp + 1, at = (n->st_cnt0 + last + 1) % p;
        k = last + 1 + (n->st_cmp + p - at) % p;
    } else {
        if (n->st_cnt0 + last >= n->st_cmp) return ~0ULL;
        k = n->st_cmp - n->st_cnt0;
    }
    return n->st_t0 + k * div;
}
void nat_st_update(struct nat *n, uint64_t now) {
    if (nat_st_match(n) <= now) n->st_sr |= 1;
    if (now > n->st_last) n->st_last = now;
}
/* The counter's value from here on counts from its last tick (the phase of HCLK/8 is kept). */
static void st_rebase(struct nat *n, uint64_t now) {
    nat_st_update(n, now);
    n->st_cnt0 = nat_st_count(n, now);
    if (n->st_ctlr & 1) n->st_t0 += st_ticks(n, now) * st_div(n); else n->st_t0 = now;
    n->st_last = now;
}
uint32_t nat_st_read(struct nat *n, uint32_t off, uint64_t now) {
    nat_st_update(n, now);
    switch (off & ~3u) {
    case 0x00: return n->st_ctlr;
    case 0x04: return n->st_sr;
    case 0x08: return (uint32_t)nat_st_count(n, now);
    case 0x0C: return (uint32_t)(nat_st_count(n, now) >> 32);
    case 0x10: return (uint32_t)n->st_cmp;
    case 0x14: return (uint32_t)(n->st_cmp >> 32);
    }
    return 0;
}
void nat_st_write(struct nat *n, uint32_t off, uint32_t value, uint64_t now) {
    uint64_t c;
    switch (off & ~3u) {
    case 0x00:
        st_rebase(n, now);
        n->st_ctlr = value & 0x8000003F;
        if (value & 0x20) { n->st_cnt0 = (value & 0x10) ? n->st_cmp : 0; n->st_ctlr &= ~0x20u; }
        break;
    case 0x04: nat_st_update(n, now); n->st_sr &= value | ~1u; break;
    case 0x08: st_rebase(n, now); n->st_cnt0 = (n->st_cnt0 & ~0xFFFFFFFFULL) | value; break;
    case 0x0C: st_rebase(n, now); c = n->st_cnt0; n->st_cnt0 = (c & 0xFFFFFFFFULL) | ((uint64_t)value << 32); break;
    case 0x10: nat_st_update(n, now); n->st_cmp = (n->st_cmp & ~0xFFFFFFFFULL) | value; n->st_last = now; break;
    case 0x14: nat_st_update(n, now); n->st_cmp = (n->st_cmp & 0xFFFFFFFFULL) | ((uint64_t)value << 32); n->st_last = now; break;
    default: return;
    }
    n->st_changed = 1;
}
int nat_st_irq(struct nat *n) { return (n->st_sr & 1) && (n->st_ctlr & 2); }
int nat_st_take_changed(struct nat *n) { int c = n->st_changed; n->st_changed = 0; return c; }
void nat_st_reset(struct nat *n) {
    n->st_ctlr = n->st_sr = 0; n->st_cnt0 = n->st_t0 = n->st_cmp = n->st_last = 0; n->st_changed = 1;
}
uint64_t nat_st_read_mmio(void *uc, uint64_t offset, unsigned size, void *user) {
    struct nat *n = user; uint32_t w = nat_st_read(n, (uint32_t)offset, nat_now(n)); (void)uc;
    return size == 4 ? w : (w >> (8 * (offset & 3))) & ((1u << (8 * size)) - 1);
}
void nat_st_write_mmio(void *uc, uint64_t offset, unsigned size, uint64_t value, void *user) {
    struct nat *n = user; uint32_t v = (uint32_t)value; (void)uc;
    if (size != 4) {   /* merge a narrower write into the register */
        uint32_t shift = 8 * (offset & 3), mask = ((size == 1 ? 0xFFu : 0xFFFFu) << shift);
        v = (nat_st_read(n, (uint32_t)offset, nat_now(n)) & ~mask) | ((v << shift) & mask);
    }
    nat_st_write(n, (uint32_t)offset, v, nat_now(n));
    if (!n->stopped_by) n->limit = n->count;   /* stop at the next block: plan the next match */
}
"""


def _library():
    lib = cbuild.load(SOURCE, "fil-bmcu-native")
    p, u64, u32, i32 = ctypes.c_void_p, ctypes.c_uint64, ctypes.c_uint32, ctypes.c_int32
    signatures = {
        "nat_new": (p, [p, u64, u64, u64, u64]), "nat_set_api": (None, [p, p, p, p]),
        "nat_free": (None, [p]), "nat_count": (u64, [p]), "nat_set_limit": (None, [p, u64]),
        "nat_stopped_by": (ctypes.c_int, [p]), "nat_exc_cause": (u32, [p]), "nat_exc_pc": (u32, [p]),
        "nat_set_irq_ready": (None, [p, ctypes.c_int]), "nat_sync": (None, [p, u64]),
        "nat_now": (u64, [p]), "nat_set_idle": (None, [p, u64, ctypes.c_int, i32]),
        "nat_idles": (u64, [p]), "nat_csr_traps": (u64, [p]), "nat_csr": (u32, [p, ctypes.c_int]),
        "nat_reset_core": (None, [p]),
        "nat_st_count": (u64, [p, u64]), "nat_st_match": (u64, [p]), "nat_st_update": (None, [p, u64]),
        "nat_st_read": (u32, [p, u32, u64]), "nat_st_write": (None, [p, u32, u32, u64]),
        "nat_st_irq": (ctypes.c_int, [p]), "nat_st_take_changed": (ctypes.c_int, [p]),
        "nat_st_reset": (None, [p]),
    }
    for name, (restype, argtypes) in signatures.items():
        fn = getattr(lib, name)
        fn.restype = restype
        fn.argtypes = argtypes
    return lib


MRET, WFI = 0x30200073, 0x10500073
STOP_LIMIT, STOP_MRET, STOP_IDLE, STOP_EXCEPTION, STOP_ENABLE, STOP_WFI = 1, 2, 3, 4, 5, 6
CSR_INTSYSCR, CSR_CORECFGR, CSR_INESTCR = 0, 1, 2
NEVER = (1 << 64) - 1


class Native:
    """The counter, the CSR emulation, the stop hooks and SysTick on one Unicorn instance.
    `special`: (address, MRET or WFI) of the image's instructions to hook; `idle`: (pc, register
    number, offset) of the executor's poll loop head and its run queue's head, or None;
    `systick_base`: where SysTick's registers are mapped."""

    def __init__(self, uc, image, base, cpi, special, idle=None, systick_base=0xE000_F000):
        from unicorn.unicorn_py3.unicorn import uclib, uc_hook_h
        import unicorn
        self.lib = lib = _library()
        self._image = (ctypes.c_uint8 * len(image)).from_buffer_copy(image)
        addr = functools.partial(ctypes.cast, typ=ctypes.c_void_p)
        lib.nat_set_api(addr(uclib.uc_emu_stop), addr(uclib.uc_reg_read), addr(uclib.uc_reg_write),
                        addr(uclib.uc_mem_read))
        self._state = state = lib.nat_new(ctypes.addressof(self._image), base, len(image), *cpi)
        if not state:
            raise MemoryError("nat_new")
        self._handles = []

        def add(kind, callback, begin, end):
            h = uc_hook_h()
            if uclib.uc_hook_add(uc._uch, ctypes.byref(h), kind, addr(callback), ctypes.c_void_p(state),
                                 ctypes.c_uint64(begin), ctypes.c_uint64(end)) != 0:
                raise RuntimeError("uc_hook_add failed")
            self._handles.append(h)

        add(unicorn.UC_HOOK_BLOCK, lib.nat_block, 1, 0)
        add(unicorn.UC_HOOK_INTR, lib.nat_intr, 1, 0)
        for address, kind in special:
            add(unicorn.UC_HOOK_CODE, lib.nat_mret if kind == MRET else lib.nat_wfi, address, address)
        if idle is not None:
            lib.nat_set_idle(state, *idle)
            add(unicorn.UC_HOOK_CODE, lib.nat_idle, idle[0], idle[0])
        if uclib.uc_mmio_map(uc._uch, ctypes.c_uint64(systick_base), ctypes.c_uint64(0x1000),
                             addr(lib.nat_st_read_mmio), ctypes.c_void_p(state),
                             addr(lib.nat_st_write_mmio), ctypes.c_void_p(state)) != 0:
            raise RuntimeError("uc_mmio_map (SysTick) failed")
        for name in ("count", "set_limit", "stopped_by", "exc_cause", "exc_pc", "set_irq_ready",
                     "sync", "now", "idles", "csr_traps", "csr", "reset_core", "st_count",
                     "st_match", "st_update", "st_read", "st_write", "st_irq", "st_take_changed",
                     "st_reset"):
            setattr(self, name, functools.partial(getattr(lib, "nat_" + name), state))

    def __del__(self):
        if getattr(self, "_state", None):
            self.lib.nat_free(self._state)
            self._state = None


def special_instructions(image, base):
    """(address, MRET or WFI) of every half-word-aligned match in the flash image (a hook at an
    address no instruction starts at never fires)."""
    found = []
    for i in range(0, len(image) - 3, 2):
        word = int.from_bytes(image[i:i + 4], "little")
        if word in (MRET, WFI):
            found.append((base + i, word))
    return found
