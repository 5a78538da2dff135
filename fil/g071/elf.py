"""Reads the firmware image: the loadable segments (flash contents and .data's initial values)
and the symbol table (the RTT control block, for `--rtt`). A minimal ELF32 little-endian reader,
so that the bench needs no package beyond Unicorn."""

import struct


def load(path):
    """(segments, symbols): segments as [(physical address, bytes)], symbols as {name: value}."""
    data = open(path, "rb").read()
    if data[:4] != b"\x7fELF" or data[4] != 1 or data[5] != 1:
        raise ValueError(f"{path}: not a 32-bit little-endian ELF")
    e_phoff, e_shoff = struct.unpack_from("<II", data, 28)
    e_phentsize, e_phnum, e_shentsize, e_shnum = struct.unpack_from("<HHHH", data, 42)
    segments = []
    for i in range(e_phnum):
        p_type, p_offset, _vaddr, p_paddr, p_filesz, _, _, _ = struct.unpack_from(
            "<IIIIIIII", data, e_phoff + i * e_phentsize)
        if p_type == 1 and p_filesz:  # PT_LOAD, placed at its load (physical) address
            segments.append((p_paddr, data[p_offset:p_offset + p_filesz]))
    sections = [struct.unpack_from("<IIIIIIIIII", data, e_shoff + i * e_shentsize)
                for i in range(e_shnum)]
    symbols = {}
    for sh in sections:
        if sh[1] != 2:  # SHT_SYMTAB
            continue
        strtab = sections[sh[6]]
        strings = data[strtab[4]:strtab[4] + strtab[5]]
        for off in range(sh[4], sh[4] + sh[5], 16):
            st_name, st_value = struct.unpack_from("<II", data, off)
            if st_name:
                end = strings.index(b"\0", st_name)
                symbols[strings[st_name:end].decode(errors="replace")] = st_value
    return segments, symbols
