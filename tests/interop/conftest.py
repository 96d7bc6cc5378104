"""Shared fixtures of the interop tests."""

import os
import shutil
import subprocess
from pathlib import Path

import pytest


@pytest.fixture
def splat_transform():
    """Runs @playcanvas/splat-transform's CLI (`-q -w` and the arguments given); skips the test
    unless SPLAT_TRANSFORM_NODE_PATH names a node_modules folder holding it (.ci/run sets it)."""
    node_path = os.environ.get("SPLAT_TRANSFORM_NODE_PATH")
    if not node_path:
        pytest.skip("set SPLAT_TRANSFORM_NODE_PATH to a node_modules folder holding @playcanvas/splat-transform")
    cli = Path(node_path) / "@playcanvas" / "splat-transform" / "bin" / "cli.mjs"
    node = shutil.which("node")
    assert node and cli.is_file(), f"node and {cli} are needed"
    return lambda *args: subprocess.run([node, str(cli), "-q", "-w", *map(str, args)], check=True, capture_output=True)
