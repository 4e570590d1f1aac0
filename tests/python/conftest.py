"""Fixtures of the Python package's tests: one tiny finished campaign, made once through
`granular.run` (2 methods x 2 replicas, N1 = 2000, t_end = 10: well under a second)."""

import copy
import shutil

import pytest

import granular

TINY = {
    "name": "py-tiny",
    "description": "the Python tests' campaign: 2 methods x 2 replicas",
    "model": "dsmc",
    "seed": 20240601,
    "replicas": 2,
    "params": {
        "method": "low_rank",
        "species": {"power_law": {"n1": 0.1, "N1": 2000, "theta": 3}},
        "restitution": {"constant": 0.5},
        "initial_temperature": 1.0,
        "t_end": 10.0,
        "output_times": {"log": {"from": 0.01, "to": 10.0, "per_decade": 5}},
        "observables": ["temperature", "msd"],
    },
    "sweep": {"method": ["low_rank", "bird"]},
}


@pytest.fixture
def tiny_manifest():
    return copy.deepcopy(TINY)


@pytest.fixture(scope="session")
def finished(tmp_path_factory):
    """A finished campaign directory (do not change it: copy it with `fresh_copy`)."""
    out = tmp_path_factory.mktemp("finished") / "runs"
    granular.run(copy.deepcopy(TINY), out=out, threads=2, progress=False)
    return out


@pytest.fixture
def fresh_copy(finished, tmp_path):
    """A copy of the finished campaign that a test may damage."""
    d = tmp_path / "copy"
    shutil.copytree(finished, d, symlinks=True)
    return d
