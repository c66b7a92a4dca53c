#!/usr/bin/env bash
# The optional srlab[baselines] extra (stable-baselines3's DQN and PPO, core/learners/baselines.py)
# in the project's .venv, on a CPU-only torch:
#
#   scripts/install-baselines.sh UV PYTHON     # what `make install-baselines` runs
#
# uv.lock resolves the extra with PyPI's torch, which on Linux x86_64 is the CUDA build
# (~5 GB of nvidia-* packages), so the extra is not installed with `uv sync --extra
# baselines`. Instead:
#   1. torch's CPU build: a wheel for this Python found in $TORCH_WHEELS (default: pip's
#      PIP_FIND_LINKS, else /opt/wheels), or else PyTorch's CPU index ($TORCH_CPU_INDEX);
#   2. the rest of the extra at uv.lock's versions, less torch and its CUDA stack: the
#      torch installed in 1 satisfies stable-baselines3's requirement, so nothing re-resolves
#      it to a CUDA build.
# A later `uv sync` (make install, when pyproject.toml or uv.lock changed) removes the extra
# again, since it syncs exactly what the lock's default extras hold; run this again then.
set -euo pipefail

UV=${1:?usage: install-baselines.sh UV PYTHON}
PY=${2:?usage: install-baselines.sh UV PYTHON}
TORCH_WHEELS=${TORCH_WHEELS:-${PIP_FIND_LINKS:-/opt/wheels}}
TORCH_CPU_INDEX=${TORCH_CPU_INDEX:-https://download.pytorch.org/whl/cpu}

say() { echo "install-baselines: $*" >&2; }

pins=$(mktemp)
trap 'rm -f "$pins"' EXIT
"$UV" export --frozen --quiet --extra ray --extra baselines --no-hashes --no-emit-project \
    --no-emit-package torch --no-emit-package triton | grep -v '^nvidia-' >"$pins"

tag=$("$PY" -c 'import sys; print(f"cp{sys.version_info[0]}{sys.version_info[1]}")')
wheel=""
for dir in ${TORCH_WHEELS//,/ }; do
    for w in "$dir"/torch-*+cpu-"$tag"-"$tag"-*linux*_$(uname -m).whl; do
        [[ -f "$w" ]] && wheel=$w
    done
done
if "$PY" -c 'import torch, sys; sys.exit(torch.version.cuda is not None)' 2>/dev/null; then
    say "a CPU-only torch is installed already"
elif [[ -n "$wheel" ]]; then
    say "torch from $wheel"
    "$UV" pip install --quiet --compile-bytecode --python "$PY" --constraint "$pins" "$wheel"
else
    say "no CPU torch wheel for $tag in $TORCH_WHEELS: torch from $TORCH_CPU_INDEX"
    "$UV" pip install --quiet --compile-bytecode --python "$PY" --index-url "$TORCH_CPU_INDEX" torch
fi
say "stable-baselines3 and the rest of the extra at uv.lock's versions"
"$UV" pip install --quiet --compile-bytecode --python "$PY" --requirement "$pins"
"$PY" - <<'EOF'
import importlib.metadata as md
import sys

import stable_baselines3
import torch

cuda = sorted(d.metadata["Name"] for d in md.distributions() if d.metadata["Name"].startswith("nvidia-"))
if torch.version.cuda is not None or cuda:
    sys.exit(f"install-baselines: torch {torch.__version__} is a CUDA build ({', '.join(cuda)})")
print(f"install-baselines: stable-baselines3 {stable_baselines3.__version__}, torch {torch.__version__} (CPU only)", file=sys.stderr)
EOF
