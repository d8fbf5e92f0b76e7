"""Files the trainers and examples/policy_onnx.py read and write (docs/training.md, "Files"):

* every file read is opened without blocking and checked before a byte is read: a regular
  file (a FIFO, device, socket or directory, or a link to one such as ``/dev/zero``, is
  refused unread) of at most a given size (:func:`open_regular`, :func:`read_regular`);
* every file written is replaced whole (:func:`atomic_write`): written under a temporary name
  beside it, created exclusively (``O_CREAT | O_EXCL | O_NOFOLLOW``: never through a link
  planted under that name), flushed, given the mode of the file it replaces, and renamed over
  it. A symbolic link as the target is refused: renaming would replace the link, not write
  its target;
* the temporary names are short and the writer's own, ``.mjskill-PID-XXXXXXXX.tmp``, so a
  run directory's cleanup (:func:`remove_stale_temps`) removes only those of writers that are
  gone, and never another name;
* :func:`fingerprint` records what a file holds (size and SHA-256), so that a resumed run can
  tell a file replaced since it started.
"""

from __future__ import annotations

import errno
import hashlib
import os
import re
import secrets
import stat

#: The prefix of every temporary file :func:`atomic_write` creates.
TEMP_PREFIX = ".mjskill-"
#: A temporary file's whole name: the prefix, the writer's pid and 8 random hex digits.
_TEMP_NAME = re.compile(r"\.mjskill-([1-9][0-9]{0,9})-([0-9a-f]{8})\.tmp\Z")
#: The largest pid Linux hands out (pid_max's upper limit, 2^22).
PID_MAX = 1 << 22


class FileCheckError(ValueError):
    """A file that is not what the reader accepts (its message names the file)."""


def kind(mode):
    """What a file of st_mode ``mode`` is, in words."""
    if stat.S_ISREG(mode):
        return "a regular file"
    if stat.S_ISDIR(mode):
        return "a directory"
    if stat.S_ISFIFO(mode):
        return "a FIFO"
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "a device"
    if stat.S_ISSOCK(mode):
        return "a socket"
    return "not a regular file"


def open_regular(path, max_bytes, what="a file"):
    """Opens ``path`` for reading (binary) without blocking, and returns the file once it is
    known to be a regular file of at most ``max_bytes`` bytes (``what`` says what it should
    be, in the error). FileCheckError otherwise, naming the file, what it is and the limit;
    OSError when it cannot be opened."""
    fd = os.open(str(path), os.O_RDONLY | getattr(os, "O_NONBLOCK", 0)
                 | getattr(os, "O_CLOEXEC", 0))
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise FileCheckError(f"{path} is {kind(st.st_mode)}, not a regular file "
                                 f"({what} is one); it was not read")
        if st.st_size > max_bytes:
            raise FileCheckError(f"{path} has {st.st_size} bytes, more than the {max_bytes} "
                                 f"read for {what}")
        if hasattr(os, "set_blocking"):
            os.set_blocking(fd, True)
        f = os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise
    return f


def read_regular(path, max_bytes, what="a file"):
    """The bytes of ``path``, read as :func:`open_regular` opens it (at most ``max_bytes``,
    even if the file grows while it is read)."""
    with open_regular(path, max_bytes, what) as f:
        data = f.read(max_bytes + 1)
    if len(data) > max_bytes:
        raise FileCheckError(f"{path} grew past the {max_bytes} bytes read for {what} while "
                             "it was read")
    return data


def _tag():
    """8 random hex digits (a temporary name's own part)."""
    return secrets.token_hex(4)


def temp_beside(path):
    """Creates an empty temporary file in ``path``'s directory, exclusively (``O_EXCL``:
    never an existing file, never through a link) with mode 0600, and returns its name:
    ``.mjskill-PID-XXXXXXXX.tmp``, short whatever ``path``'s length."""
    d = os.path.dirname(os.path.abspath(str(path)))
    flags = (os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0)
             | getattr(os, "O_CLOEXEC", 0))
    for _ in range(100):
        tmp = os.path.join(d, f"{TEMP_PREFIX}{os.getpid()}-{_tag()}.tmp")
        try:
            fd = os.open(tmp, flags, 0o600)
        except FileExistsError:
            continue  # another file (or a link) holds that name: never written through
        os.close(fd)
        return tmp
    raise FileExistsError(errno.EEXIST, "no free temporary name after 100 tries", d)


def _new_file_mode():
    """The mode ``open(path, "w")`` gives a new file: 0666 less the umask."""
    mask = os.umask(0o022)
    os.umask(mask)
    return 0o666 & ~mask


def atomic_write(path, write):
    """Calls ``write(tmp)`` for a temporary file beside ``path`` (:func:`temp_beside`),
    gives it the mode of the file it replaces (a new file's: 0666 less the umask), flushes it
    to disk and renames it over ``path``: a write that fails or a process killed at any
    moment leaves the old file or the new one, never a truncated one, and nothing is written
    through a link. ``path`` itself must not be a symbolic link (ValueError naming its
    target): the rename would replace the link, not write its target."""
    path = str(path)
    if os.path.islink(path):
        raise ValueError(f"{path} is a symbolic link (to {os.readlink(path)}); files are "
                         "replaced whole, by renaming a new file over them, never written "
                         "through a link: give the link's target "
                         f"({os.path.realpath(path)}) or remove the link")
    try:
        st = os.stat(path)
        mode = stat.S_IMODE(st.st_mode) if stat.S_ISREG(st.st_mode) else _new_file_mode()
    except FileNotFoundError:
        mode = _new_file_mode()
    tmp = temp_beside(path)
    try:
        write(tmp)
        fd = os.open(tmp, os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0)
                     | getattr(os, "O_CLOEXEC", 0))
        try:
            if not stat.S_ISREG(os.fstat(fd).st_mode):
                raise OSError(errno.EINVAL, "the temporary file is no longer a regular file",
                              tmp)
            os.fchmod(fd, mode)
            os.fsync(fd)
        finally:
            os.close(fd)
        os.replace(tmp, path)
    except BaseException:
        if os.path.lexists(tmp):
            os.remove(tmp)
        raise


def process_alive(pid):
    """Whether process ``pid`` exists (False for a number no pid can be)."""
    if not 0 < pid <= PID_MAX:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def remove_stale_temps(directory):
    """Removes from ``directory`` the temporary files of :func:`atomic_write` whose writer is
    gone (a run killed while saving): regular files named exactly
    ``.mjskill-PID-XXXXXXXX.tmp`` whose pid is not this process's and runs no process. Any
    other name (``results.tmp-2024``, ``x.tmp-99999999999999999999``) and links are left
    alone. Returns the names removed."""
    removed = []
    for name in os.listdir(directory):
        m = _TEMP_NAME.match(name)
        if not m:
            continue
        pid = int(m.group(1))
        if pid == os.getpid() or pid > PID_MAX or process_alive(pid):
            continue
        p = os.path.join(directory, name)
        try:
            if stat.S_ISREG(os.lstat(p).st_mode):
                os.remove(p)
                removed.append(name)
        except FileNotFoundError:
            pass  # gone meanwhile
    return removed


def sha256(path, max_bytes):
    """The SHA-256 (hex) of the regular file ``path`` (at most ``max_bytes``), read in
    pieces."""
    h = hashlib.sha256()
    with open_regular(path, max_bytes) as f:
        while True:
            piece = f.read(1 << 20)
            if not piece:
                break
            h.update(piece)
    return h.hexdigest()


def fingerprint(path, max_bytes):
    """What the file ``path`` holds, as a checkpoint records it: its absolute path, size and
    SHA-256."""
    return {"path": os.path.abspath(str(path)), "size": os.stat(path).st_size,
            "sha256": sha256(path, max_bytes)}


def changed_since(saved, max_bytes):
    """For fingerprints ``saved`` (:func:`fingerprint`'s), the reasons the files differ now:
    a list of "PATH: what changed" (empty when every file holds what it held)."""
    out = []
    for fp in saved:
        path = fp["path"]
        try:
            now = fingerprint(path, max_bytes)
        except (OSError, ValueError) as e:
            out.append(f"{path}: cannot be read now ({getattr(e, 'strerror', None) or e})")
            continue
        if now["size"] != fp["size"] or now["sha256"] != fp["sha256"]:
            out.append(f"{path}: {fp['size']} bytes with SHA-256 {fp['sha256'][:16]}... when "
                       f"the run started, {now['size']} bytes with {now['sha256'][:16]}... now")
    return out
