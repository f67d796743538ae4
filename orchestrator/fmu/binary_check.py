"""Is an FMU's binary a shared library this process can load? Checked before ``dlopen``.

``dlopen`` of a file that is not a shared library fails with a message fmpy turns into a plain ``Exception``;
``dlopen`` of a *truncated* one maps segments beyond the end of the file and the process dies of SIGBUS on
the first access. :func:`shared_library_problem` reads the ELF header and the program headers (the
segments ``dlopen`` maps) so that both become an :class:`~orchestrator.fmu.errors.FMUError` naming the file.
"""
from __future__ import annotations

import platform
import struct

#: ELF ``e_machine`` of the host architectures (``platform.machine()``); other hosts are not checked.
HOST_MACHINES = {"x86_64": 62, "amd64": 62, "aarch64": 183, "arm64": 183}
_ELF_MAGIC = b"\x7fELF"
_ELFCLASS64 = 2
_LITTLE_ENDIAN = 1
_ET_DYN = 3
_PT_LOAD = 1
#: ``e_ident`` (16 bytes), then e_type .. e_shstrndx of an ELF64 header (64 bytes in all).
_HEADER = struct.Struct("<16sHHIQQQIHHHHHH")
#: p_type, p_flags, p_offset, p_vaddr, p_paddr, p_filesz, p_memsz, p_align of an ELF64 program header.
_PROGRAM_HEADER = struct.Struct("<IIQQQQQQ")


def shared_library_problem(data: bytes, platform_folder: str) -> str | None:
    """What keeps ``data`` from being loaded as a shared library here (None when it looks loadable).

    Parameters
    ----------
    data : bytes
        The binary from ``binaries/<platform>/<modelIdentifier>.so``.
    platform_folder : str
        ``"linux64"`` (FMI 2.0) or ``"x86_64-linux"`` (FMI 3.0), for messages.

    Returns
    -------
    str or None
        e.g. ``"is not an ELF file (it starts with b'#!/bin/sh\\n')"`` or ``"is truncated: ..."``.
    """
    if len(data) < 4 or data[:4] != _ELF_MAGIC:
        return f"is not an ELF shared library (it starts with {data[:12]!r})" if data else "is an empty file"
    if len(data) < _HEADER.size:
        return f"is truncated: {len(data)} bytes, shorter than an ELF header"
    ident, e_type, e_machine, _, _, phoff, shoff, _, _, phentsize, phnum, shentsize, shnum, _ = _HEADER.unpack_from(data)
    if ident[4] != _ELFCLASS64 or ident[5] != _LITTLE_ENDIAN:
        return f"is a {'32' if ident[4] == 1 else 'non-64'}-bit or big-endian ELF file, not a {platform_folder} library"
    if e_type != _ET_DYN:
        return f"is an ELF file of type {e_type}, not a shared library (type 3)"
    host = HOST_MACHINES.get(platform.machine().lower())
    if host is not None and e_machine != host:
        return f"is built for ELF machine {e_machine}, this computer is {platform.machine()} (machine {host})"
    if phentsize < _PROGRAM_HEADER.size or phoff + phnum * phentsize > len(data):
        return f"is truncated: {len(data)} bytes, its program headers end at byte {phoff + phnum * phentsize}"
    for k in range(phnum):
        p_type, _, offset, _, _, filesz, _, _ = _PROGRAM_HEADER.unpack_from(data, phoff + k * phentsize)
        if p_type == _PT_LOAD and offset + filesz > len(data):
            return f"is truncated: {len(data)} bytes, a loadable segment ends at byte {offset + filesz}"
    if shoff and shoff + shnum * shentsize > len(data):
        return f"is truncated: {len(data)} bytes, its section headers end at byte {shoff + shnum * shentsize}"
    return None
