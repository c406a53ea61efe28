"""The dtype rule shared by LAC's chain and SAC-Lag's critics: "auto" is bfloat16 only where the
CPU multiplies bfloat16 natively."""

from lac_rllib.constrained import precision


def test_auto_is_bfloat16_only_with_native_bf16_matmuls(monkeypatch):
    for flags, expected in (({"avx2", "avx512f"}, "float32"), ({"avx2", "avx512_bf16"}, "bfloat16"),
                            ({"amx_bf16"}, "bfloat16"), (set(), "float32")):
        monkeypatch.setattr(precision, "cpu_flags", lambda flags=flags: flags)
        assert precision.resolve_dtype("auto") == expected
        assert precision.resolve_dtype("float32") == "float32"  # an explicit dtype is kept
        assert precision.resolve_dtype("bfloat16") == "bfloat16"


def test_cpu_flags_reads_this_machines_cpuinfo():
    flags = precision.cpu_flags()
    with open("/proc/cpuinfo") as f:
        line = next(line for line in f if line.startswith("flags"))
    assert flags == set(line.split(":", 1)[1].split()) and flags
