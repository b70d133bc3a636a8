"""The heavy verbs' BLAS threads: one per library unless GECGEN_BLAS_THREADS says otherwise."""
import pytest
from conftest import ROBOTS
from threadpoolctl import threadpool_info

from gecgen.cli import main
from gecgen.runtime.threads import one_blas_thread


@one_blas_thread
def blas_pools() -> set[int]:
    return {pool["num_threads"] for pool in threadpool_info() if pool["user_api"] == "blas"}


def test_the_heavy_verbs_run_with_the_threads_asked_for_and_restore_the_caller_s(monkeypatch):
    before = {pool["num_threads"] for pool in threadpool_info() if pool["user_api"] == "blas"}
    monkeypatch.delenv("GECGEN_BLAS_THREADS", raising=False)
    assert blas_pools() == {1}
    monkeypatch.setenv("GECGEN_BLAS_THREADS", "2")
    assert blas_pools() == {2}
    assert {pool["num_threads"] for pool in threadpool_info() if pool["user_api"] == "blas"} == before


@pytest.mark.parametrize("value", ["0", "two", "-1"])
def test_a_bad_thread_count_is_refused_in_one_line(monkeypatch, capsys, tmp_path, value):
    monkeypatch.setenv("GECGEN_BLAS_THREADS", value)
    data = tmp_path / "d.csv"
    assert main(["simulate", str(ROBOTS / "industrial6r.yaml"), "--poses", "20", "-o", str(data)]) == 0
    capsys.readouterr()
    assert main(["identify", str(ROBOTS / "industrial6r.yaml"), str(data), "-o", str(tmp_path / "c.json")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"GECGEN_BLAS_THREADS='{value}': give a whole number" in err[0], err
