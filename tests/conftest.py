"""Fixtures shared across test modules."""
import pytest


@pytest.fixture(scope="session")
def paper_fea_dir(tmp_path_factory):
    """One directory for the paper's FEA cases (Tables 1 and 2 on the default mesh, and the
    scorecard's extra cases), so the modules that check them solve each case once per
    worker session. scripts/test runs pytest-xdist with ``--dist loadscope`` (a module's
    tests on one worker), so a module-scoped fixture such as the scorecard is built once.
    (``--dist loadgroup`` with ``xdist_group`` marks did not keep the marked tests on one
    worker with the installed pytest-xdist 3.8.)"""
    return tmp_path_factory.mktemp("paper")
