"""Run directories (docs/training.md, "Stopping, continuing"): one writer at a time (a lock
file naming its pid), a ``log.csv`` appended to and flushed row by row and never rewritten in
place, checkpoints checked when read, and SIGINT/SIGTERM as a request to stop after the
current iteration. Every file is replaced whole (training.files.atomic_write), and the cleanup
removes only the temporary files that writer makes."""

from __future__ import annotations

import csv
import errno
import os
import signal
import stat
import sys

from policy_onnx import load_policy
from training.files import atomic_write, kind, process_alive, remove_stale_temps  # noqa: F401

#: The run directory's lock file: held (flock) by the trainer that writes the directory, and
#: naming its pid. One name for every trainer, so that one run at a time writes a directory.
RUN_LOCK = ".run.lock"


def hold_run_dir(out, script):
    """Makes the run directory ``out`` and takes its lock (RUN_LOCK, never through a
    symlink), so that one trainer at a time writes there: a second one, new or --resume,
    exits with an error naming the holder's pid (``script`` names the trainer in messages).
    Returns the open lock file; the lock lasts as long as this process (or until the file is
    closed). Then removes the temporary files that runs killed while saving left there
    (training.files.remove_stale_temps: only its own ``.mjskill-PID-XXXXXXXX.tmp`` names, of
    pids that run no process)."""
    import fcntl

    os.makedirs(out, exist_ok=True)
    path = os.path.join(out, RUN_LOCK)
    try:
        # O_NONBLOCK: a FIFO planted under the name is refused below, never waited on.
        fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | os.O_NONBLOCK, 0o644)
    except OSError as e:
        if e.errno == errno.ELOOP:
            sys.exit(f"error: run directory {out}: its lock file {path} is a symbolic link, "
                     f"which {script} never writes through; remove the link")
        sys.exit(f"error: run directory {out}: cannot create its lock file {path}: {e}")
    mode = os.fstat(fd).st_mode
    if not stat.S_ISREG(mode):
        os.close(fd)
        sys.exit(f"error: run directory {out}: its lock file {path} is {kind(mode)}, not a "
                 f"regular file; {script} neither reads nor locks it: remove it")
    os.set_blocking(fd, True)
    f = os.fdopen(fd, "r+")
    holder = None
    try:
        fcntl.flock(f.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        holder = f.read(64).strip() or "unknown"
    except OSError:
        # No locks on this file system: the pid in the file, if its process runs, holds it.
        pid = f.read(64).strip()
        if pid.isdigit() and int(pid) != os.getpid() and process_alive(int(pid)):
            holder = pid
    if holder is not None:
        f.close()
        sys.exit(f"error: run directory {out} is in use by another trainer (pid {holder}, "
                 f"which holds {path}); wait for it to finish or stop it, or train into "
                 "another --out")
    f.seek(0)
    f.truncate()
    f.write(f"{os.getpid()}\n")
    f.flush()
    os.fsync(f.fileno())
    remove_stale_temps(out)
    return f


def load_checkpoint(run, keys, script):
    """The checkpoint of run directory ``run`` (``checkpoint.pt``), which must hold ``keys``;
    exits with an error naming the file when it cannot be read (damaged, cut short, not
    ``script``'s)."""
    import torch

    path = os.path.join(run, "checkpoint.pt")
    why = None
    try:
        ckpt = torch.load(path, weights_only=True)
    except Exception as e:  # noqa: BLE001 - torch raises many kinds for a bad file
        why = f"it cannot be read ({type(e).__name__})"
    else:
        missing = ([k for k in keys if k not in ckpt] if isinstance(ckpt, dict)
                   else list(keys))
        if missing:
            why = f"it lacks {', '.join(missing)}"
    if why:
        sys.exit(f"error: --resume {run}: {path} is not a checkpoint of {script}: {why}; "
                 "it is damaged (a full disk, a copy cut short) or another file. The run's "
                 "policies are still in policy.onnx and best.onnx there")
    return ckpt


def save_torch(path, state):
    """``torch.save(state, path)``, replacing the file whole."""
    import torch

    atomic_write(path, lambda tmp: torch.save(state, tmp))


def check_checkpoint_is_the_runs(out, command, robot, mode):
    """--resume: refuses a checkpoint of another run (a copy from another directory), whose
    training command, robot or control mode differ from those of the run directory's
    policy.onnx (written with the checkpoints; its env id may be retargeted)."""
    path = os.path.join(out, "policy.onnx")
    if not os.path.isfile(path):
        return
    try:
        meta = {p.key: p.value for p in load_policy(path).metadata_props}
    except Exception:  # noqa: BLE001 - an unreadable file has nothing to compare
        return
    mine = dict(training_command=command, robot_uids=robot, control_mode=mode)
    diff = [k for k, v in mine.items() if k in meta and meta[k] != v]
    if diff:
        sys.exit(f"error: --resume {out}: checkpoint.pt is not this run's: its "
                 + "; ".join(f"{k} is {mine[k]!r}, the run's policy.onnx has {meta[k]!r}"
                             for k in diff)
                 + ". Resume the directory the checkpoint came from")


def start_log(log_path, header, resume_at=None, script="this trainer"):
    """Opens the run's log.csv (columns ``header``) for appending; returns (file, csv
    writer). A new run starts it with the header. A resumed run (``resume_at``: the
    (iteration, count) its checkpoint continues from, compared with the first two columns)
    keeps the rows the checkpoint counts; rows after it (written after the checkpoint by a run
    then killed) and a row cut short are dropped. The log is never rewritten in place: a new
    one is written beside it and renamed over it, so a failing write (a full disk) leaves the
    log as it was."""
    def write(rows):
        def w(tmp):
            with open(tmp, "w", newline="") as f:
                csv.writer(f).writerows(rows)
        atomic_write(log_path, w)

    if resume_at is None or not os.path.exists(log_path):
        write([header])
    else:
        first_it, count = resume_at
        with open(log_path, newline="") as f:
            text = f.read()
        rows = list(csv.reader(text.splitlines()))
        if not rows or rows[0] != header:
            sys.exit(f"error: {log_path} does not start with {script}'s header "
                     f"({','.join(header)}); it is not this script's log")
        body = rows[1:]
        if text and not text.endswith("\n") and body:
            body = body[:-1]  # cut short by a kill

        def counted(r):
            try:
                return len(r) == len(header) and int(r[0]) < first_it and int(r[1]) <= count
            except ValueError:
                return False

        kept = [r for r in body if counted(r)]
        if len(kept) != len(rows) - 1:
            print(f"{log_path}: {len(rows) - 1 - len(kept)} row(s) after the checkpoint or cut "
                  "short dropped", flush=True)
            write([header] + kept)
    log = open(log_path, "a", newline="")
    return log, csv.writer(log)


def append_row(log, writer, row):
    """Appends ``row`` to the log and flushes it to disk (before any checkpoint counts it)."""
    writer.writerow(row)
    log.flush()
    os.fsync(log.fileno())


def stop_on_signals():
    """SIGINT or SIGTERM ends the run after the current iteration (the trainer checks the
    returned list, non-empty once a signal came); a second one stops it at once."""
    stopping = []

    def on_signal(signum, frame):
        if stopping:
            signal.signal(signum, signal.SIG_DFL)
            raise KeyboardInterrupt
        stopping.append(signum)
        print(f"signal {signum}: stopping after this iteration (again to stop at once)",
              flush=True)

    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, on_signal)
    return stopping
