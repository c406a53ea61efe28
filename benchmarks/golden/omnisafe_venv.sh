#!/usr/bin/env bash
# Builds a venv of its own with OmniSafe 0.5.0 (the reference implementation of most baselines) on this
# machine's Python 3.11, for running the reference's code beside the project (golden steps, side-by-side
# timing). Never a dependency of the project. usage: benchmarks/golden/omnisafe_venv.sh DIR   (about 1.6 GiB, ~2 min)
# Why each step: OmniSafe's own `pip install` fails on cp311 (pygame 2.1.0 has no wheel; only the keyboard
# viewer needs it); safety-gymnasium 1.0.0 imports the multi-agent tasks, hence gymnasium-robotics and a
# pinned pettingzoo (an unpinned one upgrades gymnasium to 1.4 and breaks safety-gymnasium); its asset
# dataclasses use numpy-array defaults, which Python 3.11 refuses: _sg_dataclass_fix.py (loaded by a .pth
# file) restores 3.10's behaviour for safety_gymnasium's classes only.
set -euo pipefail
dir=${1:?usage: benchmarks/golden/omnisafe_venv.sh DIR}
here=$(cd "$(dirname "$0")" && pwd)
python3.11 -m venv "$dir"
"$dir/bin/pip" install -q -U pip
"$dir/bin/pip" install -q torch==2.13.0
"$dir/bin/pip" install -q --no-deps omnisafe==0.5.0 safety-gymnasium==1.0.0 gymnasium-robotics==1.2.2
"$dir/bin/pip" install -q "numpy<2" gymnasium==0.28.1 mujoco==2.3.3 "xmltodict>=0.13.0" "pyyaml>=6.0" \
  "imageio>=2.27.0" "tensorboard>=2.8.0" "wandb>=0.13.0" "moviepy>=1.0.0" "typing-extensions>=4.0.0" \
  "typer[all]>=0.7.0" "seaborn>=0.12.2" pandas==2.0.3 "matplotlib>=3.7.1" "gdown>=4.6.0"
"$dir/bin/pip" install -q pettingzoo==1.23.1 gymnasium==0.28.1 "numpy<2"
site=$("$dir/bin/python" -c 'import site; print(site.getsitepackages()[0])')
cp "$here/_sg_dataclass_fix.py" "$site/"
echo "import _sg_dataclass_fix" >"$site/_sg_dataclass_fix.pth"
"$dir/bin/python" -c 'import omnisafe, safety_gymnasium; print("omnisafe", omnisafe.__version__, "ready")'
