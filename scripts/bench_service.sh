#!/usr/bin/env bash
# Service latencies over a real socket with curl (medians): a 10,000-measurement batch upload, an
# identification job from submission to success, compensation of 1,000 targets, a plain GET.
# Starts its own server on a temporary database.   scripts/bench_service.sh
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --quiet --release
tmp=$(mktemp -d)
port=$(python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')
target/release/robocal serve --db "$tmp/bench.db" --bind "127.0.0.1:$port" >"$tmp/serve.log" 2>&1 &
server=$!
trap 'kill $server 2>/dev/null; rm -rf "$tmp"' EXIT
API=http://127.0.0.1:$port; J='Content-Type: application/json'
for _ in $(seq 100); do curl -sf "$API/readyz" >/dev/null && break; sleep 0.1; done
target/release/robocal simulate --seed 1 --out $tmp/sim.json >/dev/null
ROBOT=$(curl -s $API/v1/robots -H "$J" -d '{"name": "b'$RANDOM'", "robot": {"preset": "irb120"}, "base_guess": {"x_mm": 160.211, "y_mm": -255.727, "z_mm": -220.548, "a_deg": 91.603, "b_deg": 0.496, "c_deg": -1.384}}' | jq -r .id)
PLATE=$(curl -s $API/v1/artefacts -H "$J" -d '{"name": "p'$RANDOM'", "distances_mm": {"d12": 300, "d13": 300, "d23": 300}, "ball_diameter_mm": 12.7}' | jq -r .id)
SID=$(curl -s $API/v1/robots/$ROBOT/sessions -H "$J" -d '{"name": "trical-1", "purpose": "identification", "instrument": "trical", "tool": {"tcp_mm": [40, 0, 130], "mass_kg": 1.7, "com_mm": [30, 0, 64]}, "artefact_id": "'$PLATE'"}' | jq -r .id)
jq -c '{measurements: .sessions[0].measurements}' $tmp/sim.json > $tmp/b360.json
# 10,000 measurements: the 360 repeated
python3 - "$tmp" <<'PY'
import json,sys
d=json.load(open(sys.argv[1]+"/b360.json"))
m=(d["measurements"]*28)[:10000]
json.dump({"measurements":m},open(sys.argv[1]+"/b10k.json","w"))
PY
echo "upload 10,000 measurements (s):"
for i in $(seq 7); do
  S2=$(curl -s $API/v1/robots/$ROBOT/sessions -H "$J" -d '{"name": "u'$i'", "purpose": "identification", "instrument": "trical", "tool": {"tcp_mm": [40, 0, 130]}, "artefact_id": "'$PLATE'"}' | jq -r .id)
  curl -s -o /dev/null -w '%{time_total}\n' $API/v1/sessions/$S2/measurements -H "$J" -d @$tmp/b10k.json
done | sort -n | awk '{a[NR]=$1} END {print "  median", a[int((NR+1)/2)]}'
curl -s -o /dev/null $API/v1/sessions/$SID/measurements -H "$J" -d @$tmp/b360.json
echo "identification job, 360 poses, submit → succeeded (s):"
for i in $(seq 7); do
  t0=$(date +%s.%N)
  JOB=$(curl -s $API/v1/robots/$ROBOT/identifications -H "$J" -d '{"sessions": ["trical-1"]}' | jq -r .id)
  until curl -s $API/v1/jobs/$JOB | jq -e '.state == "succeeded"' >/dev/null; do sleep 0.005; done
  t1=$(date +%s.%N); echo "$t1 - $t0" | bc
done | sort -n | awk '{a[NR]=$1} END {print "  median", a[int((NR+1)/2)]}'
SET=$(curl -s $API/v1/robots/$ROBOT/parameter-sets | jq -r '.[0].id')
python3 - "$tmp" <<'PY'
import json,sys
t=[]
for i in range(1000):
    q=[(i*7)%60-30, (i*3)%40-10, (i*5)%50-30, (i*11)%90-45, 30+(i%40), (i*13)%180-90]
    t.append({"id":str(i),"joints_deg":q})
json.dump({"targets":t},open(sys.argv[1]+"/t1k.json","w"))
PY
echo "compensate 1,000 nominal joint targets (s):"
for i in $(seq 11); do
  curl -s -o /dev/null -w '%{time_total}\n' $API/v1/robots/$ROBOT/compensate -H "$J" -d "$(jq -c '. + {parameter_set_id: "'$SET'"}' $tmp/t1k.json)"
done | sort -n | awk '{a[NR]=$1} END {print "  median", a[int((NR+1)/2)]}'
curl -s $API/v1/robots/$ROBOT/compensate -H "$J" -d "$(jq -c '. + {parameter_set_id: "'$SET'"}' $tmp/t1k.json)" | jq .failed
echo "GET /v1/robots/{id} (s):"
for i in $(seq 51); do curl -s -o /dev/null -w '%{time_total}\n' $API/v1/robots/$ROBOT; done | sort -n | awk '{a[NR]=$1} END {print "  median", a[int((NR+1)/2)]}'
