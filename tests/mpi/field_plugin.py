"""Run under mpiexec like `parsph`: declares one extra particle field, then runs the parsph
command line with the remaining arguments. The field is declared here and nowhere else;
the test checks that it migrates, checkpoints, restarts and shows in snapshots.

usage: mpiexec -n P python field_plugin.py run SCENE [options]
"""

import sys

import numpy as np

from parsph.fields import Field, register


def tag(X, gid):
    """A value that identifies the particle: its global id and its reference position."""
    return gid.astype(np.float64) + 1e-3 * np.round(1e3 * X[:, 0]) + 1e-6 * np.round(1e3 * X[:, -1])


if __name__ == "__main__":  # declared here only, so that importing `tag` declares nothing
    register(Field("tag", "scalar", units="1", initial=tag, doc="test field: identifies its particle"))
    from parsph.cli import main

    sys.exit(main(sys.argv[1:]))
