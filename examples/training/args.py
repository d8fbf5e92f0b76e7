"""argparse value types and the option handling of ``--resume`` that the trainers share."""

from __future__ import annotations

import argparse
import os
import shlex
import sys


def int_at_least(least, what):
    """argparse type: an integer >= ``least`` (``what`` says which in the error)."""
    def parse(text):
        try:
            v = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
        if v < least:
            raise argparse.ArgumentTypeError(f"{v} {what}")
        return v
    return parse


#: argparse types: integers >= 1 and >= 0.
positive = int_at_least(1, "is not a positive integer (>= 1)")
non_negative = int_at_least(0, "is negative")


def same_dir(a, b):
    """Whether paths ``a`` and ``b`` name the same directory (or, not existing, the same
    path)."""
    try:
        return os.path.samefile(a, b)
    except OSError:
        return os.path.realpath(a) == os.path.realpath(b)


def option_names(argv):
    """The option names in ``argv`` (``--x`` of ``--x V`` and ``--x=V``)."""
    return [a.split("=", 1)[0] for a in argv if a.startswith("--")]


def without_option(argv, name):
    """``argv`` without the option ``name`` (``name V`` and ``name=V``)."""
    out, skip = [], False
    for a in argv:
        if skip:
            skip = False
        elif a == name:
            skip = True
        elif not a.startswith(name + "="):
            out.append(a)
    return out


def command_line(argv=None):
    """The command that runs this script with ``argv`` (default: this process's), as a
    policy file's ``training_command`` records it."""
    argv = sys.argv[1:] if argv is None else argv
    return "python " + " ".join(shlex.quote(a) for a in [sys.argv[0], *argv])


def changed_options(args, saved, names, differs=None):
    """The ``--option`` names among ``names`` whose values differ between the parsed options
    ``args`` and ``saved`` (``differs(name, a, b)`` compares where ``!=`` does not fit)."""
    def diff(k):
        a, b = getattr(args, k), getattr(saved, k)
        return differs(k, a, b) if differs else a != b
    return ["--" + k.replace("_", "-") for k in names if diff(k)]
