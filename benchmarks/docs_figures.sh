#!/usr/bin/env bash
# Regenerate every speed figure quoted in docs/speed.md, docs/analysis.md and docs/ct.md (one thread each).
#   bash benchmarks/docs_figures.sh            # all of them (~1 h on the shared 2-core machine)
#   bash benchmarks/docs_figures.sh analysis   # docs/analysis.md "Speed"
#   bash benchmarks/docs_figures.sh ct         # docs/ct.md "Speed" and contact table (512^3 scan cached in scan512.npy)
#   bash benchmarks/docs_figures.sh dump       # docs/speed.md "Text dump parsing"
#   bash benchmarks/docs_figures.sh liggghts   # docs/speed.md "LIGGGHTS decks against a bare run"
#   bash benchmarks/docs_figures.sh ranks      # docs/speed.md "2 MPI ranks against 1" (run it with nothing else on the machine)
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
py="${PYTHON:-python}"
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1 OVITO_THREAD_COUNT=1 NUMBA_NUM_THREADS=1
what="${1:-all}"
if [[ "$what" == all || "$what" == analysis ]]; then
  "$py" "$here/bench_analysis.py" --repeat 5
fi
if [[ "$what" == all || "$what" == ct ]]; then
  "$py" "$here/bench_ct.py" --size 512 --cache "${SCAN_CACHE:-scan512.npy}"
fi
if [[ "$what" == all || "$what" == dump ]]; then
  "$py" "$here/bench_foundation.py" --skip-cases --repeat 7
fi
if [[ "$what" == all || "$what" == liggghts ]]; then
  "$py" "$here/bench_liggghts_speed.py" --steps 3000 --warm 500
fi
if [[ "$what" == all || "$what" == ranks ]]; then
  "$py" "$here/bench_ranks.py" "$here/../cases/shear_cell_default.yaml"
  "$py" "$here/bench_ranks.py" "$here/../cases/triaxial_small.yaml" \
    --set '{"scene": {"axial_strain": 0.005, "frames": 2, "isotropic": {"max_chunks": 2, "drag_ramp": 0}}}'
fi
