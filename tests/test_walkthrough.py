"""The README's "Your own robot, step by step", run as written: its shell block, in a fresh folder
that holds the checkout's tests/data, with the installed `gecgen` on the PATH."""
import os
import re
import subprocess
import sys

import pytest
from conftest import ROOT

from gecgen.runtime.compiled import compiler


@pytest.mark.skipif(compiler() is None, reason="needs a C compiler")
def test_the_readme_walkthrough_runs_as_written(tmp_path):
    readme = (ROOT / "README.md").read_text()
    block = re.search(r"<!-- walkthrough -->\n```sh\n(.*?)```\n<!-- /walkthrough -->", readme, re.S).group(1)
    (tmp_path / "tests").symlink_to(ROOT / "tests")
    env = {**os.environ, "PATH": f"{os.path.dirname(sys.executable)}{os.pathsep}{os.environ.get('PATH', '')}"}
    run = subprocess.run(["bash", "-e", "-c", block], cwd=tmp_path, capture_output=True, text=True, env=env)
    assert run.returncode == 0, run.stderr[-2000:]
    for f in ("my_ur10/calibration/calibration.json", "my_ur10/calibration/report.html",
              "my_ur10/controller/ur10_calibration.h"):
        assert (tmp_path / f).is_file(), f
    printed = run.stdout.strip().splitlines()[-6:]  # the example program: one corrected joint per line
    assert [line.split()[0] for line in printed] == ["shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint",
                                                     "wrist_1_joint", "wrist_2_joint", "wrist_3_joint"]
