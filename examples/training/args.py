"""argparse value types and the option handling of ``--resume`` that the trainers share."""

from __future__ import annotations

import argparse
import math
import os
import re
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


def _number(text):
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None


def finite_at_least_zero(text):
    """argparse type: a finite float >= 0."""
    v = _number(text)
    if not (math.isfinite(v) and v >= 0):
        raise argparse.ArgumentTypeError(f"{v} must be a finite number >= 0")
    return v


def finite_positive(text):
    """argparse type: a finite float > 0."""
    v = finite_at_least_zero(text)
    if v == 0:
        raise argparse.ArgumentTypeError("0 must be > 0")
    return v


def number_in(low, high, what=""):
    """argparse type: a float from ``low`` to ``high`` (``what`` says what the range means,
    in the error)."""
    def parse(text):
        v = _number(text)
        if not low <= v <= high:  # NaN too
            raise argparse.ArgumentTypeError(f"{v} is out of range: {low} .. {high}{what}")
        return v
    return parse


def nonempty(text):
    """argparse type: a path that is not the empty string."""
    if text == "":
        raise argparse.ArgumentTypeError("'' is empty; give a directory")
    return text


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


#: A token argparse takes as a value, not an option, though it starts with "-".
_NEGATIVE_NUMBER = re.compile(r"-\d+\Z|-\d*\.\d+\Z")


def with_values(argv, name, values):
    """``argv`` with the option ``name`` (``nargs="+"``: ``name V...`` and ``name=V``, every
    occurrence) replaced by ``name`` with ``values``, at the end."""
    out, skip = [], False
    for a in argv:
        if skip and not (a.startswith("-") and not _NEGATIVE_NUMBER.match(a)):
            continue
        skip = False
        if a == name:
            skip = True
        elif not a.startswith(name + "="):
            out.append(a)
    return out + [name, *values]


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
