#!/usr/bin/env bash
# Rewrites the golden tracks CSVs (run from the repository root only when tracks are meant to change).
set -euo pipefail
G=tests/data/golden
T=$(mktemp -d)
tbd-taichi simulate --shape 50 50 --frames 70 --snr 2 --seed 3 --out "$T/sim50.npz"
tbd-taichi simulate --shape 100 120 --frames 60 --snr 1.6 --targets 2 --seed 5 --motion transit --out "$T/sim100.npz"
python -c "import numpy as np, sys; np.save('$G/sim50_checksum.npy', np.float64(np.load('$T/sim50.npz')['frames'].sum()))"
for e in taichi numpy; do
  tbd-taichi track "$T/sim50.npz" --method sgds --engine $e --seed 1 --out $G/sgds_sim50_$e.csv
  tbd-taichi track "$T/sim50.npz" --method pf --engine $e --seed 1 --out $G/pf_sim50_$e.csv
  tbd-taichi track "$T/sim100.npz" --method sgds --engine $e --seed 2 --paths online --out $G/sgds_sim100_online_$e.csv
  tbd-taichi track "$T/sim100.npz" --method pf --engine $e --seed 2 --snr 1.6 --particles 20000 --out $G/pf_sim100_$e.csv
  tbd-taichi track tests/data/IR_DRONE_021.mp4 --real-video --engine $e --out $G/sgds_drone021_real_$e.csv
  # Algorithm 2's uniform hand-over draw and no backfill, as the SGDS files were before the multi-frame hand-over
  H="--param handover_frames=0 --param backfill_frames=0"
  tbd-taichi track "$T/sim50.npz" --method sgds --engine $e --seed 1 $H --out $G/sgds_sim50_handover0_$e.csv
  tbd-taichi track "$T/sim100.npz" --method sgds --engine $e --seed 2 --paths online $H \
    --out $G/sgds_sim100_online_handover0_$e.csv
done
