#!/bin/bash
# One device call for issue 32 (see docs/baselines.md): profile one PPO update, train the eight
# cases x 2 seeds in two resumed legs (16 GPU processes, then 8 GPU + 8 CPU), export, evaluate.
# As run on a lent machine (docs/baselines.md, "The paper's budget"): from the folder above
# .devwork/, which held scripts/, src/growspace_sim/, src/growspace_camera/ and whl/ (the
# wheels of gymnasium, farama-notifications, stable-baselines3 and mlxtend); writes at most 8
# files into $OUT, the folder the machine hands back.
set -u
T0=$(date +%s)
BUDGET=${BUDGET:-470}  # seconds this script may take in all
el() { echo $(( $(date +%s) - T0 )); }
cd .devwork || exit 1
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade \
  --target /tmp/site whl/*.whl || exit 1
export PYTHONPATH=/tmp/site:$PWD/src/growspace_sim PYTHONUNBUFFERED=1 OMP_NUM_THREADS=1 \
  MKL_NUM_THREADS=1
nvidia-smi --query-gpu=name,memory.total,driver_version,clocks.sm --format=csv,noheader
echo "cores: $(nproc --all)  $(grep -m1 'model name' /proc/cpuinfo)"
python3 -c "import sys, torch, stable_baselines3, gymnasium, numpy, numba; print(sys.version.split()[0], 'torch', torch.__version__, 'sb3', stable_baselines3.__version__, 'gym', gymnasium.__version__, 'numpy', numpy.__version__, 'numba', numba.__version__)" || exit 1
CASES=Control-Easy,Control-Hard,FindPlant-Easy,FindPlant-Hard,Fairness-Easy,Fairness-Hard,Shape-Easy,Shape-Hard
echo "== [$(el) s] profile: one PPO update, one process alone, cuda"
timeout 120 python3 scripts/learning_budget.py profile --device cuda --updates 3 \
  --configs dummy:sb3:8,native:sb3:8,native:device:8,native:device:32 --json $OUT/profile_cuda.json
echo "== [$(el) s] profile: cpu, one thread"
timeout 45 python3 scripts/learning_budget.py profile --device cpu --updates 1 \
  --configs native:device:8
timeout 240 nvidia-smi --query-gpu=timestamp,utilization.gpu,memory.used \
  --format=csv,noheader -l 20 | sed 's/^/gpu: /' &
echo "== [$(el) s] train leg A: 16 processes on cuda"
python3 scripts/learning_budget.py train --out /tmp/runs --cases $CASES --seeds 2 \
  --minutes 1.5 --device cuda
B=$(python3 -c "print(round(min(1.5, ($BUDGET - $(el) - 190) / 60), 2))")
echo "== [$(el) s] train leg B (resumed, $B min): seed 0 on cuda, seed 1 on cpu, 16 at once"
if python3 -c "import sys; sys.exit($B < 0.4)"; then
  python3 scripts/learning_budget.py train --out /tmp/runs --cases $CASES --seeds 1 \
    --minutes $B --device cuda > /tmp/legB_cuda.txt 2>&1 &
  GPU=$!
  python3 scripts/learning_budget.py train --out /tmp/runs --cases $CASES --seeds 1 \
    --first-seed 1 --minutes $B --device cpu > /tmp/legB_cpu.txt 2>&1 &
  CPU=$!
  wait $GPU $CPU
  cat /tmp/legB_cuda.txt /tmp/legB_cpu.txt
fi
echo "== [$(el) s] export"
python3 scripts/learning_budget.py export --out /tmp/runs --export $OUT
echo "== [$(el) s] evaluate (60 episodes, seeds 10000..) and camera loop (20 episodes)"
mkdir -p /tmp/eval
LEFT=$(( BUDGET - $(el) - 8 ))
if [ $LEFT -gt 20 ]; then
  for c in control findplant fairness shape; do
    [ -f $OUT/policy-$c.pt ] || continue
    mkdir -p /tmp/pol_$c && ln -sf $OUT/policy-$c.pt /tmp/pol_$c/
    for half in 0 1; do
      timeout $LEFT python3 scripts/learning_budget.py camera --policies /tmp/pol_$c \
        --episodes 10 --seed $((10000 + 10 * half)) --json /tmp/eval/cam_${c}_$half.json \
        > /tmp/eval/cam_${c}_$half.log 2>&1 &
    done
  done
  timeout $LEFT python3 -m growspace_sim.learn.evaluate_policies \
    $(for r in /tmp/runs/ppo-*; do echo --run $r; done) --episodes 60 --workers 8 \
    --out /tmp/eval > /tmp/eval/compare.log 2>&1
  wait
  tail -n 3 /tmp/eval/*.log
fi
tar czf $OUT/eval.tar.gz -C /tmp eval 2>/dev/null
echo "== [$(el) s] done"
