"""Shared fixtures: the data folder (../shared/data, or LWSCCD_DATA_DIR) and the main program
(LWSCCD_CCD_PROGRAM, else a build folder's), each skipped with a visible reason when absent."""
import os
import pathlib
import shutil

import pytest

REPO = pathlib.Path(__file__).resolve().parents[2]


@pytest.fixture(scope="session")
def data_dir() -> pathlib.Path:
    path = pathlib.Path(os.environ.get("LWSCCD_DATA_DIR", REPO.parent / "shared" / "data"))
    if not (path / "scenes").is_dir():
        pytest.skip(f"SKIPPED: no test data at {path} (set LWSCCD_DATA_DIR)")
    return path


@pytest.fixture(scope="session")
def ccd_program() -> str:
    candidates = [os.environ.get("LWSCCD_CCD_PROGRAM", "")]
    candidates += [str(REPO / b / "examples" / "lwsccd-ccd") for b in ("build-tests", "build", "build-examples")]
    candidates.append(shutil.which("lwsccd-ccd") or "")
    for c in candidates:
        if c and os.access(c, os.X_OK):
            return c
    pytest.skip("SKIPPED: the main program lwsccd-ccd is not built (set LWSCCD_CCD_PROGRAM)")
