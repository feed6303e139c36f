#!/bin/bash
# Throughput probe (fresh runs, not results): 16 GPU processes with 32 envs x 64 steps, then
# 8 GPU processes (32 envs) beside 8 CPU processes (8 envs). Run as budget_call.sh is.
set -u
cd .devwork || exit 1
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade \
  --target /tmp/site whl/*.whl || exit 1
export PYTHONPATH=/tmp/site:$PWD/src/growspace_sim PYTHONUNBUFFERED=1 OMP_NUM_THREADS=1 MKL_NUM_THREADS=1
CASES=Control-Easy,Control-Hard,FindPlant-Easy,FindPlant-Hard,Fairness-Easy,Fairness-Hard,Shape-Easy,Shape-Hard
echo "== probe A: 16 on cuda, 32 envs"
python3 scripts/learning_budget.py train --out /tmp/probeA --cases $CASES --seeds 2 --first-seed 10 \
  --minutes 1.2 --device cuda --n-envs 32
echo "== probe B: 8 on cuda (32 envs) + 8 on cpu (8 envs)"
python3 scripts/learning_budget.py train --out /tmp/probeB --cases $CASES --seeds 1 --first-seed 10 \
  --minutes 1.2 --device cuda --n-envs 32 > /tmp/pB_cuda.txt 2>&1 &
G=$!
python3 scripts/learning_budget.py train --out /tmp/probeB --cases $CASES --seeds 1 --first-seed 11 \
  --minutes 1.2 --device cpu --n-envs 8 > /tmp/pB_cpu.txt 2>&1 &
C=$!
wait $G $C
cat /tmp/pB_cuda.txt /tmp/pB_cpu.txt
mkdir -p /tmp/probe && cp /tmp/probeA/call_*.json /tmp/probeB/call_*.json /tmp/probe/
tar czf $OUT/probe.tar.gz -C /tmp probe
