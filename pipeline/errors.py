"""One error path for every ``cryograting`` command.

A mistake in what the user gave (a file, an option, data) ends a command with one line
on stderr, ``cryograting <command>: error: <what was wrong>``, and exit code 2; an
interrupt (Ctrl-C) with ``interrupted`` and 130. ``--debug`` (anywhere on the command
line) shows the Python traceback instead. Anything else is a bug and keeps its traceback.

The line names the file or option: an ``OSError`` by its file name; an I/O, decoding or
numeric error whose text names none of the files the command was given gets them appended
(``(files given: --sag map.npz)``), so an error deep in a reader still points at the file
that caused it; and the API names of the command's options are written as the command
line spells them (``window_um=0`` -> ``--window-um 0``). A sweep whose cases failed lists
them, one line each, after the cases that succeeded were cached.
"""

from __future__ import annotations

import re
import sys
import zipfile

from pipeline.sweeps.sweep import SweepError

__all__ = ["USER_ERRORS", "cli_spelling", "command_options", "describe", "pop_debug", "run_command"]

#: What bad input raises: missing or unwritable files (OSError), wrong values and
#: undecodable text (ValueError, UnicodeDecodeError), numbers out of range
#: (OverflowError, ZeroDivisionError, FloatingPointError), empty or truncated files
#: (EOFError, zipfile.BadZipFile), an optional dependency not installed (ImportError).
USER_ERRORS = (OSError, ValueError, ArithmeticError, EOFError, zipfile.BadZipFile, ImportError)

#: argparse destinations that name input files -> their spelling on the command line.
INPUT_OPTIONS = {"sag": "--sag", "manifest": "MANIFEST", "config": "CONFIG.toml", "check": "--check",
                 "result": "RESULT", "displacement_csv": "--displacement-csv", "nodes": "--nodes"}
#: ... and those that name output locations.
OUTPUT_OPTIONS = {"out": "--out", "cache_dir": "--cache-dir"}
#: Destinations of a study config source: a command with one also knows config keys named
#: like its options (``mesh_size_mm``), so only the options the user gave are re-spelled.
CONFIG_SOURCES = ("config", "check", "preset", "set")


def pop_debug(argv) -> tuple[list[str], bool]:
    """``argv`` without ``--debug`` and whether it was there (accepted before or after the command)."""
    argv = list(sys.argv[1:] if argv is None else argv)
    return [a for a in argv if a != "--debug"], "--debug" in argv


def command_options(parser, command: str, args=None) -> dict[str, str]:
    """``dest -> --option`` of the long options of ``parser``'s subcommand ``command``
    (with ``args`` of a command that reads a study config: only the options given)."""
    sub = next((a.choices[command] for a in parser._actions  # argparse keeps its actions here
                if isinstance(getattr(a, "choices", None), dict) and command in a.choices), None)
    if sub is None:
        return {}
    opts = {a.dest: a.option_strings[-1] for a in sub._actions
            if a.option_strings and a.option_strings[-1].startswith("--") and a.dest != "help"}
    if args is not None and any(d in vars(args) for d in CONFIG_SOURCES):
        opts = {d: o for d, o in opts.items() if getattr(args, d, None) != sub.get_default(d)}
    return opts


def cli_spelling(text: str, options: dict[str, str]) -> str:
    """``text`` with the API names of the command's options in their command-line spelling:
    ``window_um=0.0`` -> ``--window-um 0.0``, ``window_um`` -> ``--window-um``. A dotted or
    prefixed name (``LsfSettings.window_um``, ``fea.t0_um``) is another thing and stays."""
    for dest, opt in options.items():
        text = re.sub(rf"(?<![\w.\-]){re.escape(dest)}=", f"{opt} ", text)
        if "_" in dest:  # identifiers only ('profiles' is also a word), not quoted names (a list of keys)
            text = re.sub(rf"(?<![\w.\-'\"]){re.escape(dest)}(?![\w='\"])", opt, text)
    return text


def _paths(args, options: dict) -> list[tuple[str, str]]:
    return [(options[k], str(v)) for k, v in sorted(vars(args).items()) if k in options and v]


def describe(exc: BaseException, args=None, options: dict[str, str] | None = None) -> str:
    """One line saying what was wrong, naming the file or the inputs of ``args``; the
    command's ``options`` (:func:`command_options`) are named as on the command line."""
    if isinstance(exc, OSError) and exc.filename is not None and exc.strerror:
        files = " -> ".join(str(f) for f in (exc.filename, exc.filename2) if f is not None)
        return f"{files}: {exc.strerror}"
    text = " ".join(str(exc).split())  # one line, whatever the library wrote
    if isinstance(exc, UnicodeDecodeError):
        text = (f"a file is not {exc.encoding.upper()} text (undecodable byte at offset {exc.start}); "
                "save it as UTF-8")
    elif isinstance(exc, ArithmeticError):
        text = f"numeric {type(exc).__name__} ({text}): an input is outside the range the computation supports"
    elif isinstance(exc, (EOFError, zipfile.BadZipFile)):
        text = f"a file is empty, truncated or not what its name says ({type(exc).__name__}: {text})"
    elif not text:
        text = type(exc).__name__
    text = cli_spelling(text, options or {})
    if args is None:
        return text
    if isinstance(exc, OSError):  # e.g. a full disk: no file name in the error
        given = _paths(args, {**INPUT_OPTIONS, **OUTPUT_OPTIONS})
    elif isinstance(exc, (UnicodeDecodeError, ArithmeticError, EOFError, zipfile.BadZipFile)):
        given = _paths(args, INPUT_OPTIONS)
    else:  # ValueErrors of the toolkit name their parameter themselves
        given = []
    mentioned = any(re.search(rf"(?<![\w./-]){re.escape(v)}(?![\w/-])", text) for _, v in given)
    if given and not mentioned:  # the library could not know the file
        text += " (files given: " + ", ".join(f"{o} {v}" if o.startswith("--") else v for o, v in given) + ")"
    return text


def run_command(func, args, command: str, debug: bool = False, options: dict[str, str] | None = None) -> int:
    """Run ``func(args)``; a user error becomes one stderr line and exit code 2.

    Under ``debug`` the exception propagates (Python prints the traceback)."""
    try:
        return int(func(args) or 0)
    except KeyboardInterrupt:
        if debug:
            raise
        print(f"cryograting {command}: interrupted", file=sys.stderr)
        return 130
    except SweepError as exc:  # a summary of the failed cases (one line each), not a traceback
        if debug:
            raise
        print(f"cryograting {command}: error: {exc}", file=sys.stderr)
        return 2
    except USER_ERRORS as exc:
        if debug:
            raise
        print(f"cryograting {command}: error: {describe(exc, args, options)}", file=sys.stderr)
        return 2
