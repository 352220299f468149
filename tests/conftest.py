"""Fixtures shared across test modules."""
import pytest


@pytest.fixture(scope="session")
def paper_fea_dir(tmp_path_factory):
    """One directory for the paper's FEA cases (Tables 1 and 2 on the default mesh, and the
    scorecard's extra cases), so the modules that check them solve each case once per
    session. Those modules carry ``xdist_group("paper_fea")``: with ``--dist loadgroup``
    (scripts/test) they run on one worker and share this directory."""
    return tmp_path_factory.mktemp("paper")
