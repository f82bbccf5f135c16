"""Suite-wide setup: hypothesis keeps its files (example database off, its constants
cache) in a temporary folder removed at the end, never in the source tree."""

import shutil
import tempfile

_home = None


def pytest_configure(config):
    global _home
    try:
        from hypothesis.configuration import set_hypothesis_home_dir
    except ImportError:
        return
    _home = tempfile.mkdtemp(prefix="unseen-hypothesis-")
    set_hypothesis_home_dir(_home)


def pytest_unconfigure(config):
    if _home is not None:
        shutil.rmtree(_home, ignore_errors=True)
