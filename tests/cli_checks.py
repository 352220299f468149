"""Checks shared by the tests of the CLI's refusals: work must not start, and the error
must be one line naming what was wrong."""


def never(*a, **k):
    """Stand-in for a function that must not be reached (monkeypatched onto work)."""
    raise AssertionError("work started although the input should have been refused first")


def one_error_line(capsys, needle):
    """The command's stderr is one line, without a traceback, containing ``needle``."""
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "Traceback" not in err[0], err
    assert needle in err[0], err[0]
    return err[0]
