# The pytest suite of the dmplatform package (Tests/python), run by ctest
# with PYTHONPATH at build/Python and DM_SOURCE_DIR / DM_DMPLATFORM set.
import os
import pathlib

import pytest


@pytest.fixture(scope="session")
def source_dir():
    return pathlib.Path(os.environ.get("DM_SOURCE_DIR", pathlib.Path(__file__).resolve().parents[2]))


@pytest.fixture(scope="session")
def dmplatform_exe():
    exe = os.environ.get("DM_DMPLATFORM")
    if not exe:
        pytest.skip("DM_DMPLATFORM is not set (ctest sets it)")
    return exe
