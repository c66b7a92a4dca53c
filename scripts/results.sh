#!/usr/bin/env bash
# Regenerate every result the README states, into docs/results/<name>/:
#
#   bash scripts/results.sh             # all of them (about 40 min on 2 cores)
#   bash scripts/results.sh obstacle    # one of them, by name
#   bash scripts/results.sh exploration # the frozen comparison at 50/200/1,000 episodes:
#                                       # run only when named (the longest folder, see below)
#
# The deep baselines (dqn, ppo) need the srlab[baselines] extra (`make install-baselines`);
# without it the experiments run without them and say so. Tuning (`srlab tune --write`)
# is not rerun here: core/data/tuned.toml holds its result, and docs/results/tuning*/
# the commands that wrote it.
set -euo pipefail
cd "$(dirname "$0")/.."

SRLAB=${SRLAB:-.venv/bin/srlab}
JOBS=${JOBS:-2}
ALL="innate,delayed,dp,rp,kp,sonar,reflexes,expert,qlambda,qlambda-hybrid"
if .venv/bin/python -c 'from core.baselines import available; raise SystemExit(not available())'; then
    ALL="$ALL,dqn,ppo"
else
    echo "results: the srlab[baselines] extra is not installed: dqn and ppo left out" >&2
fi
COMMON=(--seeds 20 --episodes 50 --eval-episodes 10 --jobs "$JOBS" --quiet)

run() {
    local name=$1
    shift
    if [[ -n "${ONLY:-}" && "$ONLY" != "$name" ]]; then
        return
    fi
    echo "results: $name" >&2
    "$SRLAB" "$@"
}

ONLY=${1:-}
run world-check world-check --sensors all --seeds 20 --episodes 50 --jobs "$JOBS" --quiet \
    --out docs/results/world-check
run obstacle experiment --conditions "$ALL" --signal given "${COMMON[@]}" --out docs/results/obstacle
run full-task experiment --conditions "$ALL" "${COMMON[@]}" --out docs/results/full-task
run classic-obstacle experiment --conditions "$ALL" --world classic --signal given "${COMMON[@]}" \
    --out docs/results/classic-obstacle
run classic-full-task experiment --conditions "$ALL" --world classic "${COMMON[@]}" \
    --out docs/results/classic-full-task
run paper-stimuli experiment --conditions dp,rp,kp,sonar,expert,qlambda-hybrid --sensors paper \
    --signal given "${COMMON[@]}" --out docs/results/paper-stimuli
run phase phase --grid docs/results/phase/grid.toml --conditions kp,sonar,rp,qlambda-hybrid,dp \
    --signal given --seeds 20 --episodes 50 --jobs "$JOBS" --quiet --out docs/results/phase
if [[ -z "$ONLY" || "$ONLY" == wrong-teacher ]]; then
    echo "results: wrong-teacher" >&2
    .venv/bin/python scripts/wrong_teacher.py docs/results/wrong-teacher --jobs "$JOBS"
fi
if [[ "$ONLY" == exploration ]]; then
    # 20 seeds x 1,250 training episodes per learner (each budget trains from scratch):
    # over an hour on 2 cores with dqn and ppo, so only when asked for by name.
    LEARNERS=kp,sonar,qlambda,qlambda-decay,qlambda-hybrid,qlambda-hybrid-decay
    if [[ "$ALL" == *dqn* ]]; then
        LEARNERS="$LEARNERS,dqn,ppo"
    fi
    echo "results: exploration" >&2
    .venv/bin/python scripts/frozen_budgets.py docs/results/exploration --learners "$LEARNERS" \
        --jobs "$JOBS"
fi
if [[ -z "$ONLY" || "$ONLY" == deep-curve ]] && [[ "$ALL" == *dqn* ]]; then
    echo "results: deep-curve" >&2
    .venv/bin/python scripts/deep_curve.py docs/results/deep-curve --episodes 1000 --seeds 3 \
        --signal given --jobs "$JOBS"
fi
