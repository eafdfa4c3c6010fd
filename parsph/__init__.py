"""parsph: MPI-parallel corrected SPH for fast-transient solid mechanics.

Compiled kernels are cached on disk by Numba, which keys a cached function by its own
source file only: a kernel that inlines functions of another module would load stale
machine code after that module changed. The cache therefore lives in a directory named
after a hash of every parsph module that holds compiled code (COMPILED_SOURCE), under
$PARSPH_CACHE_DIR or ~/.cache/parsph/numba: any change of such a module starts a new,
empty cache, never a stale one. Set before Numba reads its configuration.
"""

import hashlib
import os
import sys

__version__ = "0.1.0"


def _compiled_source() -> str:
    """Hash of the text of every module of the package that uses Numba."""
    root = os.path.dirname(os.path.abspath(__file__))
    digest = hashlib.sha256()
    for folder, dirs, files in sorted(os.walk(root)):
        dirs.sort()
        for name in sorted(files):
            if name.endswith(".py"):
                path = os.path.join(folder, name)
                with open(path, "rb") as fh:
                    text = fh.read()
                if b"numba" in text:
                    digest.update(os.path.relpath(path, root).encode() + b"\0" + text)
    return digest.hexdigest()[:16]


COMPILED_SOURCE = _compiled_source()
CACHE_ROOT = os.environ.get("PARSPH_CACHE_DIR") or os.path.join(
    os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache"), "parsph", "numba")
NUMBA_CACHE = os.path.join(CACHE_ROOT, COMPILED_SOURCE)
os.environ["NUMBA_CACHE_DIR"] = NUMBA_CACHE
if "numba" in sys.modules:  # imported first: its configuration is read already
    sys.modules["numba"].config.CACHE_DIR = NUMBA_CACHE
