"""The golden fixtures (tests/fixtures/golden/): each names the reference and version that recorded
it and the CPU it was recorded on, and the loader refuses one that does not name its reference; the
comparison names every output that differs."""

import json

import numpy as np
import pytest

from tests.algorithms.golden import FIXTURES, FixtureError, assert_matches, load


def test_every_fixture_names_its_reference_version_command_and_cpu_and_is_in_the_readme():
    readme = (FIXTURES / "README.md").read_text(encoding="utf-8")
    names = sorted(p.stem for p in FIXTURES.glob("*.npz"))
    assert len(names) >= 4
    for name in names:
        fx = load(name)
        assert fx.meta["reference_version"] and fx.meta["command"]
        # another CPU rounds the float64 products otherwise: the arrays agree to ~1e-12 (docs/golden.md)
        assert fx.meta["cpu"]["model_name"] and isinstance(fx.meta["cpu"]["simd_flags"], list), name
        assert f"`{name}.npz`" in readme, f"{name}.npz is not described in tests/fixtures/golden/README.md"
        assert fx.outputs, name


def test_a_fixture_without_its_reference_version_is_refused(tmp_path):
    with np.load(FIXTURES / "ppo_lag-omnisafe.npz") as z:
        arrays = {k: z[k] for k in z.files}
    meta = json.loads(str(arrays["meta"]))
    del meta["reference_version"]
    arrays["meta"] = np.array(json.dumps(meta))
    np.savez(tmp_path / "ppo_lag-omnisafe.npz", **arrays)
    with pytest.raises(FixtureError, match=r"lacks \['reference_version'\]"):
        load("ppo_lag-omnisafe", tmp_path)
    with pytest.raises(FixtureError, match="no golden fixture"):
        load("sac_lag-nowhere", tmp_path)


def test_the_comparison_names_each_output_that_differs():
    expected = {"loss_pi": np.float64(1.0), "grad/w": np.ones(3), "after/w": np.zeros(2)}
    assert_matches({"loss_pi": 1.0 + 1e-7, "grad/w": np.ones(3), "after/w": np.zeros(2)}, expected)
    with pytest.raises(AssertionError) as err:
        assert_matches({"loss_pi": 1.001, "grad/w": np.array([1.0, 1.0, 1.1])}, expected)
    message = str(err.value)
    assert "loss_pi: max relative error 0.001" in message and "grad/w: max relative error 0.1" in message
    assert "after/w: not computed" in message
