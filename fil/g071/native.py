"""The bench's only C: an instruction counter and the hooks on the few instructions Unicorn's
Cortex-M0 model does not handle as the chip does, compiled once with the system's C compiler and
called from Unicorn's C side.

Why C: a Python callback per translated block or per instruction runs the firmware at 1/200 to
1/600 of real time (docs/firmware-in-the-loop.md). Here Unicorn calls C for every block (to count
instructions, the bench's clock) and for four instructions only; Python runs only at MMIO
accesses and between slices.

- Block hook: adds the block's instruction count to a 64-bit counter and stops the emulation once
  the counter reaches the slice's limit (virtual time derives from this count; it is exact per
  block and deterministic, never taken from the wall clock).
- SEV (0xBF40): Unicorn executes it as a NOP. Here it sets the event register (ARMv6-M ARM, B1.5.18
  "Wait For Event and Send Event").
- WFE (0xBF20): Unicorn reports it as an invalid instruction. Here, with the event register set,
  the event is consumed and execution goes on; otherwise the emulation stops and the bench sleeps
  until an event (an interrupt).
- WFI (0xBF30): Unicorn stops, like a halt. Here the hook records that the stop is a WFI.
- CPSIE i (0xB662): if an interrupt is pending and enabled, the emulation stops after it so that
  the bench takes the interrupt at once (not at the end of the slice).
"""

import ctypes
import functools

import cbuild

SOURCE = r"""
#include <stdint.h>
#include <stdlib.h>
typedef int (*stop_fn)(void *);
static stop_fn uc_stop;
/* One per Unicorn instance (the hooks' user data), so that several benches share the library. */
struct nat {
    const uint8_t *image; uint64_t base, length;
    uint64_t count, limit;
    int event, irq_ready, stopped_by;   /* stopped_by: 0 none, 1 limit, 2 WFE, 3 WFI, 4 CPSIE, 5 WFE consumed */
};
void nat_set_stop(stop_fn f) { uc_stop = f; }
struct nat *nat_new(const uint8_t *img, uint64_t b, uint64_t len) {
    struct nat *n = calloc(1, sizeof *n);
    if (n) { n->image = img; n->base = b; n->length = len; n->limit = ~0ULL; }
    return n;
}
void nat_free(struct nat *n) { free(n); }
uint64_t nat_count(struct nat *n) { return n->count; }
void nat_set_limit(struct nat *n, uint64_t l) { n->limit = l; n->stopped_by = 0; }
int nat_stopped_by(struct nat *n) { return n->stopped_by; }
void nat_set_event(struct nat *n, int e) { n->event = e; }
int nat_event(struct nat *n) { return n->event; }
void nat_set_irq_ready(struct nat *n, int r) { n->irq_ready = r; }
void nat_block(void *uc, uint64_t address, uint32_t size, void *user) {
    struct nat *n = user;
    uint64_t offset = address - n->base;
    if (address >= n->base && offset + size <= n->length) {
        uint32_t i = 0;
        while (i < size) {
            uint16_t top = (uint16_t)(n->image[offset + i] | (n->image[offset + i + 1] << 8)) >> 11;
            i += (top == 0x1d || top == 0x1e || top == 0x1f) ? 4 : 2;
            n->count++;
        }
    } else {
        n->count += size / 2;
    }
    if (n->count >= n->limit && !n->stopped_by) { n->stopped_by = 1; uc_stop(uc); }
}
void nat_sev(void *uc, uint64_t address, uint32_t size, void *user) {
    (void)uc; (void)address; (void)size;
    ((struct nat *)user)->event = 1;
}
void nat_wfe(void *uc, uint64_t address, uint32_t size, void *user) {
    struct nat *n = user;
    (void)address; (void)size;
    if (n->event) { n->event = 0; n->stopped_by = 5; } else { n->stopped_by = 2; }
    uc_stop(uc);
}
void nat_wfi(void *uc, uint64_t address, uint32_t size, void *user) {
    (void)address; (void)size;
    ((struct nat *)user)->stopped_by = 3;
    uc_stop(uc);
}
void nat_cpsie(void *uc, uint64_t address, uint32_t size, void *user) {
    struct nat *n = user;
    (void)address; (void)size;
    if (n->irq_ready) { n->stopped_by = 4; uc_stop(uc); }
}
"""


def _library():
    lib = cbuild.load(SOURCE, "fil-g071-native")
    p = ctypes.c_void_p
    lib.nat_new.restype = p
    lib.nat_new.argtypes = [p, ctypes.c_uint64, ctypes.c_uint64]
    lib.nat_set_stop.argtypes = [p]
    lib.nat_free.argtypes = [p]
    lib.nat_count.restype = ctypes.c_uint64
    lib.nat_count.argtypes = [p]
    lib.nat_set_limit.argtypes = [p, ctypes.c_uint64]
    for name in ("nat_stopped_by", "nat_event"):
        getattr(lib, name).argtypes = [p]
    for name in ("nat_set_event", "nat_set_irq_ready"):
        getattr(lib, name).argtypes = [p, ctypes.c_int]
    return lib


SEV, WFE, WFI, CPSIE = 0xBF40, 0xBF20, 0xBF30, 0xB662
STOP_LIMIT, STOP_WFE, STOP_WFI, STOP_CPSIE, STOP_WFE_CONSUMED = 1, 2, 3, 4, 5


class Native:
    """The counter and special-instruction hooks installed on one Unicorn instance."""

    def __init__(self, uc, image, base, special_addresses):
        from unicorn.unicorn_py3.unicorn import uclib, uc_hook_h
        import unicorn
        self.lib = lib = _library()
        self._image = (ctypes.c_uint8 * len(image)).from_buffer_copy(image)
        lib.nat_set_stop(ctypes.cast(uclib.uc_emu_stop, ctypes.c_void_p))
        self._state = state = lib.nat_new(ctypes.addressof(self._image), base, len(image))
        if not state:
            raise MemoryError("nat_new")
        self._handles = []

        def add(kind, callback, begin, end):
            h = uc_hook_h()
            cb = ctypes.cast(callback, ctypes.c_void_p)
            if uclib.uc_hook_add(uc._uch, ctypes.byref(h), kind, cb, ctypes.c_void_p(state),
                                 ctypes.c_uint64(begin), ctypes.c_uint64(end)) != 0:
                raise RuntimeError("uc_hook_add failed")
            self._handles.append(h)

        add(unicorn.UC_HOOK_BLOCK, lib.nat_block, 1, 0)
        callbacks = {SEV: lib.nat_sev, WFE: lib.nat_wfe, WFI: lib.nat_wfi, CPSIE: lib.nat_cpsie}
        for address, kind in special_addresses:
            add(unicorn.UC_HOOK_CODE, callbacks[kind], address, address)
        bind = functools.partial
        self.count = bind(lib.nat_count, state)
        self.set_limit = bind(lib.nat_set_limit, state)
        self.stopped_by = bind(lib.nat_stopped_by, state)
        self.set_event = bind(lib.nat_set_event, state)
        self.event = bind(lib.nat_event, state)
        self.set_irq_ready = bind(lib.nat_set_irq_ready, state)

    def __del__(self):
        # The hooks go with the Unicorn instance; the state is freed with it.
        if getattr(self, "_state", None):
            self.lib.nat_free(self._state)
            self._state = None


def special_instructions(segments, base, size):
    """Addresses of SEV, WFE, WFI and CPSIE i in the image's flash (any halfword-aligned match:
    a hook at an address no instruction starts at never fires)."""
    found = []
    for address, data in segments:
        if not (base <= address < base + size):
            continue
        for i in range(0, len(data) - 1, 2):
            hw = data[i] | (data[i + 1] << 8)
            if hw in (SEV, WFE, WFI, CPSIE):
                found.append((address + i, hw))
    return found
