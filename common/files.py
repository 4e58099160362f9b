"""The one bounded reader: every file the project opens (YAML, JSON, policy zips, replay buffers) is read here.

A file's size header cannot be trusted: a device file (``/dev/zero``, ``/dev/urandom``) reports
0 bytes and never ends, a FIFO blocks its reader until someone writes, and a symlink may point
at either. So :func:`read_bytes`

* resolves symlinks first, and names the target in its refusal;
* reads regular files only: a directory, a character or block device, a FIFO or a socket is
  refused, from its ``stat``, *before* it is opened (so a FIFO never blocks), and checked again
  on the open handle (the file may have been swapped in between);
* reads at most ``limit`` bytes whatever the size header says: it asks for ``limit + 1`` and
  refuses the file if it got them.

Every refusal is a one-line :class:`ConfigError` (file, problem). Standard library only.
"""

from __future__ import annotations

import errno
import io
import json
import lzma
import os
import stat
import struct
import zipfile
import zlib
from pathlib import Path
from typing import Any, BinaryIO

from common.errors import ConfigError

_CHUNK = 1024 * 1024

MAX_STATE_BYTES = 1024 * 1024  # a run's state.json or run.json (a few kB; 100 stages would be 50 kB)
MAX_DIGITS = 4300  # Python's int <-> str limit (sys.get_int_max_str_digits): past it int("9" * n) is a ValueError


def size_text(size: int) -> str:
    """A byte count as people write it: ``2 MiB``, ``64 KiB``, ``100 bytes``."""
    for unit, scale in (("GiB", 2**30), ("MiB", 2**20), ("KiB", 2**10)):
        if size >= scale:
            return f"{size / scale:.1f}".removesuffix(".0") + f" {unit}"
    return f"{size} bytes"


def _kind(mode: int) -> str | None:
    """What a file that is not a regular file is (None for a regular file)."""
    if stat.S_ISREG(mode):
        return None
    for test, name in ((stat.S_ISDIR, "a directory"), (stat.S_ISCHR, "a character device"),
                       (stat.S_ISBLK, "a block device"), (stat.S_ISFIFO, "a FIFO (named pipe)"),
                       (stat.S_ISSOCK, "a socket")):
        if test(mode):
            return name
    return "not a regular file"


def _refuse_os_error(path: Path, error: OSError, expected: str) -> ConfigError:
    if error.errno in (errno.ENOENT, errno.ENOTDIR):
        return ConfigError(path, None, "no such file")
    if error.errno == errno.ELOOP:
        return ConfigError(path, None, f"a symlink loop; expected {expected}")
    reason = error.strerror or type(error).__name__
    return ConfigError(path, None, f"cannot be read ({reason.lower()}); expected {expected}")


def regular_file(path: str | Path, expected: str = "a file") -> Path:
    """``path`` with its symlinks resolved, if it is a regular file; else a one-line :class:`ConfigError`.

    Nothing is opened: a FIFO is refused from its ``stat`` alone.
    """
    path = Path(path)
    try:
        real = path.resolve(strict=True)
        mode = os.stat(real).st_mode
    except RuntimeError:  # Path.resolve's answer to a symlink loop before Python 3.13
        raise ConfigError(path, None, f"a symlink loop; expected {expected}") from None
    except OSError as error:
        raise _refuse_os_error(path, error, expected) from None
    except ValueError:  # a NUL in the name
        raise ConfigError(path, None, f"not a valid file name; expected {expected}") from None
    kind = _kind(mode)
    if kind is not None:
        via = f"resolves to {real}, " if real != Path(os.path.abspath(path)) else ""
        raise ConfigError(path, None, f"{via}{kind}, not a regular file; expected {expected}")
    return real


def open_regular(path: str | Path, limit: int, expected: str = "a file", too_large: str | None = None) -> BinaryIO:
    """The regular file ``path`` opened for reading in binary, if its size is at most ``limit``.

    For a caller that reads a part at a time (a zip's members, say); the caller closes it. Its
    reads are no longer bounded by this module: use :func:`read_bytes` to read a file whole.
    """
    path = Path(path)
    real = regular_file(path, expected)
    flags = os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_NOCTTY", 0) | getattr(os, "O_CLOEXEC", 0)
    try:
        # O_NONBLOCK: should a FIFO be swapped in after the check above, opening it does not wait for a writer.
        descriptor = os.open(real, flags)
    except OSError as error:
        raise _refuse_os_error(path, error, expected) from None
    try:
        info = os.fstat(descriptor)
        kind = _kind(info.st_mode)
        if kind is not None:  # swapped in since regular_file() looked
            raise ConfigError(path, None, f"{kind}, not a regular file; expected {expected}")
        if info.st_size > limit:
            raise _too_large(path, limit, expected, too_large)
        return os.fdopen(descriptor, "rb")
    except BaseException:
        os.close(descriptor)
        raise


def _too_large(path: Path, limit: int, expected: str, too_large: str | None) -> ConfigError:
    return ConfigError(path, None, f"larger than {size_text(limit)}; {too_large or f'expected {expected} of at most {size_text(limit)}'}")


def read_bytes(path: str | Path, limit: int, expected: str = "a file", too_large: str | None = None) -> bytes:
    """At most ``limit`` bytes of the regular file ``path``, or a one-line :class:`ConfigError`.

    ``expected`` says what the file should have been (``"a YAML file"``); ``too_large`` replaces
    the advice given for a file over ``limit``. The size header is checked first, and then not
    trusted: ``limit + 1`` bytes are asked for, and getting them refuses the file.
    """
    path = Path(path)
    with open_regular(path, limit, expected, too_large) as handle:
        try:
            # One read of what the size header promises, plus a byte to see whether it lied; a file
            # that did (a /proc file says 0 bytes) is read on, in chunks, up to limit + 1 bytes.
            data = handle.read(min(os.fstat(handle.fileno()).st_size, limit) + 1)
            chunks, total = [data], len(data)
            while data and total <= limit:
                data = handle.read(min(_CHUNK, limit + 1 - total))
                chunks.append(data)
                total += len(data)
        except OSError as error:
            raise _refuse_os_error(path, error, expected) from None
    if total > limit:  # the size header lied, or the file grew while being read
        raise _too_large(path, limit, expected, too_large)
    return chunks[0] if len(chunks) <= 2 and not chunks[-1] else b"".join(chunks)


def open_zip(file: bytes | BinaryIO, source: str | Path | None, field: str | None, max_members: int,
             max_directory: int, expected: str = "a zip") -> zipfile.ZipFile:
    """A zip (bytes, or a seekable binary file) whose member count and central directory are
    bounded from its end record *before* :mod:`zipfile` lists the members: listing a million
    empty members is a minute and gigabytes.

    :mod:`zipfile` reads as many members as the directory's *size* holds, whatever the count
    beside it says, so both are checked (from the very record ``ZipFile`` reads next), and the
    count again once listed. Reading a member stays the caller's: check its ``file_size`` first.
    """
    def refuse(problem: str) -> ConfigError:
        return ConfigError(source, field, problem)

    handle = io.BytesIO(file) if isinstance(file, (bytes, bytearray)) else file
    try:
        end = zipfile._EndRecData(handle)  # what ZipFile() reads first; None if there is no end record
    except (OSError, ValueError, OverflowError, struct.error):
        end = None
    if not end:
        raise refuse(f"not a zip file; expected {expected}")
    if end[zipfile._ECD_LOCATION] + zipfile.sizeEndCentDir + end[zipfile._ECD_COMMENT_SIZE] != handle.seek(0, io.SEEK_END):
        # A zip ends with its end record; one found earlier is a member's own (a policy's weights
        # are a zip inside the zip) in a file cut short.
        raise refuse(f"a truncated or damaged zip (its end record is not at its end); expected {expected}")
    count, directory = end[zipfile._ECD_ENTRIES_TOTAL], end[zipfile._ECD_SIZE]
    if count > max_members or directory > max_directory:
        raise refuse(f"a zip of {count:,} members in a directory of {size_text(directory)}; allowed: at most "
                     f"{max_members} members in {size_text(max_directory)}; expected {expected}")
    try:
        archive = zipfile.ZipFile(handle)
    except (zipfile.BadZipFile, OSError, ValueError, EOFError, NotImplementedError, OverflowError, struct.error) as exc:
        raise refuse(f"a damaged zip ({' '.join(str(exc).split())[:80]}); expected {expected}") from None
    if len(archive.infolist()) > max_members:
        archive.close()
        raise refuse(f"a zip of more than {max_members} members; expected {expected}")
    return archive


def zip_damage(exc: BaseException) -> str:
    """What reading a zip member that raised ``exc`` (one of :data:`ZIP_DAMAGE`) says about the zip."""
    text = " ".join(str(exc).split())
    if "CRC" in text:
        return "its CRC-32 does not match its data (a damaged or edited zip)"
    if isinstance(exc, (EOFError, zlib.error, lzma.LZMAError)) or "size" in text.lower():
        return "its data does not match its size header (a damaged or edited zip)"
    return f"cannot be read from the zip ({text[:80] or type(exc).__name__})"


# What reading a damaged member raises: zipfile's BadZipFile (a bad CRC-32, a size header that
# lies, a local header that disagrees), the decompressors' errors, an unsupported method or encryption.
ZIP_DAMAGE = (zipfile.BadZipFile, zlib.error, lzma.LZMAError, EOFError, NotImplementedError, RuntimeError,
              ValueError, OSError, struct.error)


def read_text(path: str | Path, limit: int, expected: str = "a text file", too_large: str | None = None) -> str:
    """A bounded regular file as UTF-8 text, line endings made ``\\n`` (as ``Path.read_text`` does)."""
    data = read_bytes(path, limit, expected, too_large)
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as error:
        raise ConfigError(path, None, f"not UTF-8 text (byte {error.start}); expected {expected}") from None
    return text.replace("\r\n", "\n").replace("\r", "\n")


def parse_json(data: bytes | str, source: str | Path | None, field: str | None = None) -> Any:
    """JSON text parsed, or a one-line :class:`ConfigError`: invalid JSON, nesting past Python's
    recursion limit, and integers past Python's :data:`MAX_DIGITS`-digit conversion limit."""
    try:
        return json.loads(data)
    except RecursionError:
        raise ConfigError(source, field, "nested too deeply; not valid JSON") from None
    except UnicodeDecodeError:
        raise ConfigError(source, field, "not UTF-8 text; not valid JSON") from None
    except json.JSONDecodeError as error:
        raise ConfigError(source, field, f"not valid JSON (line {error.lineno}: {error.msg})") from None
    except ValueError:  # int("9" * 5000): Python refuses to convert more digits than its limit
        raise ConfigError(source, field, f"holds an integer of more than {MAX_DIGITS} digits; not valid here") from None


def read_json(path: str | Path, limit: int, expected: str = "a JSON file") -> Any:
    """A bounded regular file parsed as JSON (see :func:`parse_json`)."""
    return parse_json(read_bytes(path, limit, expected), path)


__all__ = ["MAX_DIGITS", "MAX_STATE_BYTES", "ZIP_DAMAGE", "open_regular", "open_zip", "parse_json", "read_bytes", "read_json", "read_text",
           "regular_file", "size_text", "zip_damage"]
