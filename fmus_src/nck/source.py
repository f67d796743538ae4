"""Reading a G-code program file: text or a clear :class:`GCodeError`, never a decoding traceback."""
from __future__ import annotations

from pathlib import Path

from .errors import GCodeError

#: Byte-order mark some Windows editors put at the start of UTF-8 files.
_BOM = b"\xef\xbb\xbf"


def read_program(path: str | Path) -> str:
    """Read a program file as UTF-8 text (ASCII is UTF-8; a leading BOM is dropped).

    Parameters
    ----------
    path : str or Path
        The program file.

    Returns
    -------
    str
        The program text, line endings as in the file.

    Raises
    ------
    GCodeError
        The file does not exist or cannot be read, is not UTF-8 text (a binary
        file; the message gives the line and byte offset of the first
        undecodable byte), or holds no program at all (empty or blanks only).
    """
    name = str(path)
    p = Path(path)
    if not p.is_file():
        raise GCodeError(name, 0, "", "an existing G-code program file", "program file not found")
    try:
        data = p.read_bytes()
    except OSError as exc:
        raise GCodeError(name, 0, "", "a readable file", f"cannot read the program file ({exc.strerror})") from None
    if data.startswith(_BOM):
        data = data[len(_BOM):]
    try:
        text = data.decode("utf-8", errors="strict")
    except UnicodeDecodeError as exc:
        line = data.count(b"\n", 0, exc.start) + 1
        if _in_comment(data, exc.start):
            raise GCodeError(
                name, line, "", "a program saved as UTF-8 or ASCII (convert the file, e.g. from Windows-1252 or "
                "CP949, or remove the character from the comment)",
                f"byte 0x{data[exc.start]:02x} at byte offset {exc.start}, inside a comment, is not UTF-8 text: "
                "the file was saved in another encoding",
            ) from None
        raise GCodeError(
            name, line, "", "a text file (ASCII or UTF-8) holding a G-code program",
            f"byte 0x{data[exc.start]:02x} at byte offset {exc.start} is not UTF-8 text: a binary file?",
        ) from None
    if not text.strip():
        raise GCodeError(name, 0, "", "a G-code program (blocks such as G0 X0 Y0)", "the program file is empty")
    return text


def _in_comment(data: bytes, offset: int) -> bool:
    """True when byte ``offset`` of ``data`` lies inside a ``( ... )`` or ``;`` comment of its line.

    A comment with an accented or Hangul character written by a Windows post-processor in its ANSI code page
    (Windows-1252, CP949) is the usual reason for a program file that is not UTF-8; the message then says so
    instead of suspecting a binary file. Same rules as the lexer: ``(`` opens a comment up to the next ``)``,
    ``;`` outside one starts a comment to the end of the line.
    """
    start = max(data.rfind(b"\n", 0, offset), data.rfind(b"\r", 0, offset)) + 1
    inside = False
    for byte in data[start:offset]:
        if inside:
            inside = byte != 0x29  # ")"
        elif byte == 0x28:  # "("
            inside = True
        elif byte == 0x3B:  # ";"
            return True
    return inside
