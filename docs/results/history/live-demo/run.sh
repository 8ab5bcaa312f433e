#!/bin/bash
# seed 0, 5k steps of the 20k schedule, default config (sigma 0), expert = bot over the wire
cd "$(git rev-parse --show-toplevel)"
export PYTHONPATH="$(git rev-parse --show-toplevel)"
PY=.venv/bin/python
OUT=runs/live-demo/seed0
mkdir -p runs/live-demo
$PY -m mrguide.cli train --expert live --port 0 --stop-after 5000 --seed 0 --quiet --out $OUT > runs/live-demo.train.log 2>&1 &
TP=$!
for i in $(seq 1 120); do grep -q "annotation page:" runs/live-demo.train.log && break; sleep 1; done
URL=$(grep "annotation page:" runs/live-demo.train.log | sed 's/annotation page: //')
$PY -m mrguide.cli annotate bot --url "$URL" --seed 0 > runs/live-demo.bot.log 2>&1
wait $TP
echo "train exit $?" >> runs/live-demo.train.log
