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
import hashlib
import os
import shutil
import subprocess
import tempfile

SOURCE = r"""
#include <stdint.h>
typedef int (*stop_fn)(void *);
static stop_fn uc_stop;
static const uint8_t *image; static uint64_t base, length;
static uint64_t count, limit;
static int event, irq_ready, stopped_by;   /* stopped_by: 0 none, 1 limit, 2 WFE, 3 WFI, 4 CPSIE */
void nat_init(stop_fn f, const uint8_t *img, uint64_t b, uint64_t len) {
    uc_stop = f; image = img; base = b; length = len; count = 0; limit = ~0ULL; event = 0;
}
uint64_t nat_count(void) { return count; }
void nat_set_limit(uint64_t l) { limit = l; stopped_by = 0; }
int nat_stopped_by(void) { return stopped_by; }
void nat_set_event(int e) { event = e; }
int nat_event(void) { return event; }
void nat_set_irq_ready(int r) { irq_ready = r; }
void nat_block(void *uc, uint64_t address, uint32_t size, void *user) {
    (void)user;
    uint64_t offset = address - base;
    if (address >= base && offset + size <= length) {
        uint32_t i = 0;
        while (i < size) {
            uint16_t top = (uint16_t)(image[offset + i] | (image[offset + i + 1] << 8)) >> 11;
            i += (top == 0x1d || top == 0x1e || top == 0x1f) ? 4 : 2;
            count++;
        }
    } else {
        count += size / 2;
    }
    if (count >= limit && !stopped_by) { stopped_by = 1; uc_stop(uc); }
}
void nat_special(void *uc, uint64_t address, uint32_t size, void *user) {
    (void)address; (void)size;
    uintptr_t kind = (uintptr_t)user;
    if (kind == 0xBF40) { event = 1; }
    else if (kind == 0xBF20) {
        if (event) { event = 0; stopped_by = 5; /* consumed: the bench skips the WFE */ uc_stop(uc); }
        else { stopped_by = 2; uc_stop(uc); }
    }
    else if (kind == 0xBF30) { stopped_by = 3; uc_stop(uc); }
    else if (kind == 0xB662) { if (irq_ready) { stopped_by = 4; uc_stop(uc); } }
}
"""


def _library():
    compiler = shutil.which(os.environ.get("CC", "cc"))
    if not compiler:
        raise RuntimeError("no C compiler (cc) found: the bench needs one for its instruction counter")
    digest = hashlib.sha256(SOURCE.encode()).hexdigest()[:12]
    path = os.path.join(tempfile.gettempdir(), f"fil-g071-native-{digest}-{os.getuid()}.so")
    if not os.path.exists(path):
        source = path[:-3] + f".{os.getpid()}.c"
        with open(source, "w") as f:
            f.write(SOURCE)
        tmp = f"{path}.{os.getpid()}.tmp"
        subprocess.run([compiler, "-O2", "-shared", "-fPIC", "-o", tmp, source], check=True)
        os.replace(tmp, path)
        os.unlink(source)
    lib = ctypes.CDLL(path)
    lib.nat_count.restype = ctypes.c_uint64
    lib.nat_set_limit.argtypes = [ctypes.c_uint64]
    lib.nat_init.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_uint64, ctypes.c_uint64]
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
        stop = ctypes.cast(uclib.uc_emu_stop, ctypes.c_void_p)
        lib.nat_init(stop, ctypes.addressof(self._image), base, len(image))
        self._handles = []
        h = uc_hook_h()
        cb = ctypes.cast(lib.nat_block, ctypes.c_void_p)
        if uclib.uc_hook_add(uc._uch, ctypes.byref(h), unicorn.UC_HOOK_BLOCK, cb, None,
                             ctypes.c_uint64(1), ctypes.c_uint64(0)) != 0:
            raise RuntimeError("uc_hook_add (block) failed")
        self._handles.append(h)
        special = ctypes.cast(lib.nat_special, ctypes.c_void_p)
        for address, kind in special_addresses:
            h = uc_hook_h()
            if uclib.uc_hook_add(uc._uch, ctypes.byref(h), unicorn.UC_HOOK_CODE, special,
                                 ctypes.c_void_p(kind), ctypes.c_uint64(address),
                                 ctypes.c_uint64(address)) != 0:
                raise RuntimeError("uc_hook_add (code) failed")
            self._handles.append(h)
        self.count = lib.nat_count
        self.set_limit = lib.nat_set_limit
        self.stopped_by = lib.nat_stopped_by
        self.set_event = lib.nat_set_event
        self.event = lib.nat_event
        self.set_irq_ready = lib.nat_set_irq_ready


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
