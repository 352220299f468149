"""The keyed result store, :mod:`fea.store`, under its pipeline name.

The store lives in the FEA layer so that the mesh and film-operator caches can use it
too; new code imports :mod:`fea.store`.
"""

from fea.store import *  # noqa: F401,F403
from fea.store import __all__  # noqa: F401
