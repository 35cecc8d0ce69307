#!/usr/bin/env bash
# Every resource of the service with curl and jq, against a running `robocal serve`
# (default http://127.0.0.1:8080; set API, and TOKEN when the server requires one).
# The measurements come from the virtual cell: `robocal simulate` writes them to a cell file,
# its true robot with a small cyclic error on joint 3 that the model lacks (the diagnosis finds it).
#   cargo run --release -- serve &      then      scripts/api_walkthrough.sh
# (tests/suite/readme.rs runs it against a server, and checks that README.md's service block is an
# excerpt of it, line for line.)
set -euo pipefail
cd "$(dirname "$0")/.."
API=${API:-http://127.0.0.1:8080}
AUTH=()
if [[ -n "${TOKEN:-}" ]]; then AUTH=(-H "Authorization: Bearer $TOKEN"); fi
J='Content-Type: application/json'
call() { curl -sS --fail-with-body "${AUTH[@]}" "$@"; }
wait_job() {  # poll a job until it ends; print it
  until call "$API/v1/jobs/$1" | jq -e '.state | test("succeeded|failed|cancelled")' >/dev/null; do sleep 0.2; done
  call "$API/v1/jobs/$1"
}
tmp=$(mktemp -d)
# The robocal binary: $ROBOCAL when set (the test sets it to its build), else cargo's release build.
robocal() { if [[ -n "${ROBOCAL:-}" ]]; then "$ROBOCAL" "$@"; else cargo run --quiet --release -- "$@"; fi; }
robocal simulate --seed 1 --effects cyclic:j=3:h=2:amp_deg=0.01 --out "$tmp/sim.json" >/dev/null
name="cell-$RANDOM$RANDOM"

echo "== a robot (preset or custom table) with a guess of its base in the artefact's frame {W}"
ROBOT=$(call "$API/v1/robots" -H "$J" -d '{"name": "'"$name"'", "robot": {"preset": "irb120"},
  "base_guess": {"x_mm": 160.211, "y_mm": -255.727, "z_mm": -220.548, "a_deg": 91.603, "b_deg": 0.496, "c_deg": -1.384}}' | jq -r .id)
call "$API/v1/robots/$ROBOT" | jq -c '{id, name, dof, parameters}'

echo "== the ball triangle from its three measured distances (the answer has the ball centres in {W})"
PLATE=$(call "$API/v1/artefacts" -H "$J" -d '{"name": "plate-'"$name"'",
  "distances_mm": {"d12": 300, "d13": 300, "d23": 300}, "ball_diameter_mm": 12.7}' | jq -r .id)
call "$API/v1/artefacts/$PLATE" | jq -c .ball_centres_mm

echo "== a pose plan (job): 360 collision-checked TriCal candidates, 75 chosen by DETMAX, 506 tracker poses"
JOB=$(call "$API/v1/robots/$ROBOT/pose-plans" -H "$J" -d '{"artefact_id": "'"$PLATE"'",
  "tool": {"tcp_mm": [40, 0, 130], "mass_kg": 1.7, "com_mm": [30, 0, 64]}, "select": {"n": 75}}' | jq -r .id)
PLAN=$(wait_job "$JOB" | jq -r .result.pose_plan_id)
call "$API/v1/pose-plans/$PLAN" | jq -c '.plan | {candidates, first: .identification[0], selection: .selection.index_final}'
call "$API/v1/robots/$ROBOT/pose-plans" | jq -c '[.[] | {id, identification, validation, candidates}]'

echo "== sessions and their measurements (JSON here; text/csv works too), idempotent uploads"
for k in 0 1 2 3; do
  s=$(jq -c ".sessions[$k] | {name, purpose, instrument, tool, order}" "$tmp/sim.json")
  SID=$(call "$API/v1/robots/$ROBOT/sessions" -H "$J" -d "$(jq -c '. + {"artefact_id": "'"$PLATE"'"}' <<<"$s")" | jq -r .id)
  jq -c "{measurements: .sessions[$k].measurements}" "$tmp/sim.json" > "$tmp/batch.json"
  call "$API/v1/sessions/$SID/measurements" -H "$J" -H "Idempotency-Key: $name-$k" -d @"$tmp/batch.json" | jq -c .
done
call "$API/v1/sessions/$SID/measurements" -H "$J" -H "Idempotency-Key: $name-3" -d @"$tmp/batch.json" -D - -o /dev/null \
  | grep -i idempotency-replayed
call "$API/v1/sessions/$SID/measurements?offset=0&limit=2" | jq -c '{total, next_offset, first: .items[0]}'

echo "== identification (job) → an immutable, versioned parameter set; a refused fit says why"
JOB=$(call "$API/v1/robots/$ROBOT/identifications" -H "$J" -d '{"sessions": ["trical-1"], "kappa_limit": 2}' | jq -r .id)
wait_job "$JOB" | jq -c '{state, error: .error.title}'
JOB=$(call "$API/v1/robots/$ROBOT/identifications" -H "$J" -d '{"sessions": ["trical-1"], "select": {"n": 75}}' | jq -r .id)
SET=$(wait_job "$JOB" | jq -r .result.parameter_set_id)

echo "== validation (job) on the tracker sessions"
JOB=$(call "$API/v1/parameter-sets/$SET/validations" -H "$J" -d '{"sessions": ["tracker-n1", "tracker-n2", "tracker-n3"]}' | jq -r .id)
VALIDATION=$(wait_job "$JOB" | jq -r .result.validation_id)
call "$API/v1/validations/$VALIDATION" | jq -c '.report | {mean_mm, median_mm, std_mm, max_mm, nominal_mean_mm: .nominal.mean_mm}'

echo "== diagnosis (job): where the set still misses, which unmodelled effect, how far the error shrinks"
JOB=$(call "$API/v1/parameter-sets/$SET/diagnoses" -H "$J" -d '{}' | jq -r .id)
DIAGNOSIS=$(wait_job "$JOB" | jq -r .result.diagnosis_id)
call "$API/v1/diagnoses/$DIAGNOSIS" | jq -c '.report | {verdict: .verdict.status, effects: [.verdict.effects[].label],
  shrink: [.shrink[] | {model, mean_mm}]}'
echo "== accepting it: the extended model as the next version (not activated); a verdict without an effect is a 409"
curl -sS "${AUTH[@]}" -X POST "$API/v1/diagnoses/$DIAGNOSIS/accept" \
  | jq -c 'if .version then {version, active, effect: [.parameter_set.parameters[].name | select(startswith("cyc"))]} else {status, detail} end'

echo "== history, explicit activation, export, import"
call "$API/v1/robots/$ROBOT/parameter-sets" | jq -c '.[] | {version, active, quality, validations: [.validations[].figures.mean_mm]}'
call -X PUT "$API/v1/robots/$ROBOT/active-parameter-set" -H "$J" -d '{"parameter_set_id": "'"$SET"'"}' | jq -c '{version, active}'
call "$API/v1/parameter-sets/$SET/export" > "$tmp/params.json" && jq -c '.parameters[1]' "$tmp/params.json"
IMPORTED=$(call "$API/v1/robots/$ROBOT/parameter-sets" -H "$J" -d @examples/irb120_table_5_1.json | jq -r .id)
call "$API/v1/parameter-sets/$IMPORTED" | jq -c '{version, active}'

echo "== corrections, each with a reason: a reading excluded and restored, a set archived, a spare session deleted"
call -X PATCH "$API/v1/sessions/$SID/measurements/0" -H "$J" -d '{"excluded": true, "reason": "walkthrough: reflector dusty"}' \
  | jq -c '{index, excluded, reason: .exclusion.reason}'
call -X PATCH "$API/v1/sessions/$SID/measurements/0" -H "$J" -d '{"excluded": false, "reason": "walkthrough: it was fine"}' \
  | jq -c '{index, excluded, history: [.history[] | {reason, restore_reason}]}'
call -X PATCH "$API/v1/parameter-sets/$IMPORTED" -H "$J" -d '{"archived": true, "reason": "walkthrough: table kept for reference only"}' \
  | jq -c '{version, archived}'
call "$API/v1/robots/$ROBOT/parameter-sets" | jq -c '[.[].version]'
SPARE=$(call "$API/v1/robots/$ROBOT/sessions" -H "$J" -d '{"name": "spare", "purpose": "validation",
  "instrument": "laser_tracker", "tool": {"tcp_mm": [0, 60, 80]}}' | jq -r .id)
call -X DELETE "$API/v1/sessions/$SPARE?reason=walkthrough:%20created%20by%20mistake" -o /dev/null -w '%{http_code}\n'
curl -sS "${AUTH[@]}" -X DELETE "$API/v1/parameter-sets/$SET" | jq -c '{status, hint}'
call "$API/v1/audit-events?robot_id=$ROBOT" | jq -c '[.[] | {action, reason}]'

echo "== compensated targets with the active set"
call "$API/v1/robots/$ROBOT/compensate" -H "$J" -d @examples/targets.json | jq -c '.results[0] | {id, joints_deg, residual_mm}'
echo "== a robot program filtered with the active set: the module back with the counts in headers; with Accept: application/json, the report"
call "$API/v1/robots/$ROBOT/programs/filter?name=weld.mod" -H 'Content-Type: application/octet-stream' --data-binary @examples/programs/weld.mod -D "$tmp/filter.h" -o "$tmp/weld.mod" && grep -i '^x-.*-targets' "$tmp/filter.h"
call "$API/v1/robots/$ROBOT/programs/filter?name=weld.mod" -H 'Content-Type: application/octet-stream' -H 'Accept: application/json' --data-binary @examples/programs/weld.mod | jq -c '{compensated, kept, failed, seam1: .targets[2] | {name, line, correction_mm, uncertainty_mm, error}}'
echo "== ISO 9283 (job): AP per pose of a tracker session's first 20 readings, nominal and with the active set (predicted)"
BODY=$(jq -nc '{session: "tracker-n1", poses: [range(20) | {index: ., pose_id: "P\(. + 1)"}], pairs: [{from: "P1", to: "P2"}]}')
JOB=$(call "$API/v1/robots/$ROBOT/iso9283" -H "$J" -d "$BODY" | jq -r .id)
ISO=$(wait_job "$JOB" | jq -r .result.evaluation_id)
call "$API/v1/iso9283/$ISO" | jq -c '.report | {nominal_ap_mm: .nominal.summary.ap_p_mean_mm, calibrated_ap_mm: .calibrated.summary.ap_p_mean_mm}'
call "$API/v1/iso9283/$ISO/report" -o "$tmp/iso9283.html" && grep -o '<title>[^<]*' "$tmp/iso9283.html"
echo "== exports (the DH table, URDF, a RAPID module of compensated targets), the history for dashboards, drift"
call "$API/v1/parameter-sets/$SET/export?format=csv-dh" > "$tmp/set.csv" && grep -E '^(row|joint3),' "$tmp/set.csv"
call "$API/v1/parameter-sets/$SET/export?format=urdf" > "$tmp/set.urdf" && grep -c '<joint ' "$tmp/set.urdf"
call "$API/v1/parameter-sets/$SET/export?format=rapid&allow_partial=true" -H "$J" -d @examples/targets.json > "$tmp/targets.mod"
grep -m 2 -E 'CONST (robtarget|jointtarget) ' "$tmp/targets.mod"
call "$API/v1/robots/$ROBOT/history?from=2020-01-01" | jq -c '.[] | {version, active, mean_mm: .validation.mean_mm, verdict: .diagnosis.verdict}'
call "$API/v1/parameter-sets/$SET/drift?against=$IMPORTED" | jq -c '.drift | {moved, identified_in_a_only: (.only_in_a | length)}'

echo "== the robot's measurements as a cell file, jobs, errors"
call "$API/v1/robots/$ROBOT/cell?sessions=trical-1" | jq -c '{robot, sessions: [.sessions[] | {name, n: (.measurements | length)}]}'
call "$API/v1/jobs?robot_id=$ROBOT&state=failed" | jq -c '[.[] | {kind, error: .error.type}]'
echo "== every list pages the same way: offset and limit; X-Total-Count and Link headers"
call -D - -o /dev/null "$API/v1/jobs?robot_id=$ROBOT&limit=2" | grep -iE '^(x-total-count|link):'
curl -sS "${AUTH[@]}" "$API/v1/robots/$ROBOT/sessions" -H "$J" -d '{"name": "x", "purpose": "identification",
  "instrument": "trical", "tool": {"tcp_mm": [0, 0, "?"]}}' | jq -c .
rm -rf "$tmp"
