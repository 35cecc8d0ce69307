#!/usr/bin/env bash
# Every HTML report in a real browser (issue 15, item 5). A release server on a fresh SQLite
# database is filled with the virtual cell (scripts/api_walkthrough.sh) and with the UR10 data set
# (imported by the CLI, uploaded with curl); the service renders the validation, identification
# (parameter set) and diagnosis reports of both, the CLI writes a study and a crossval report; each
# page is loaded in headless Chromium, which
#   - takes a screenshot, checked not blank (distinct colours, non-white fraction);
#   - dumps the DOM, checked for every expected plot (<svg> elements, each with its drawing);
#   - logs the console, checked empty (no error, no refused load, no "Uncaught").
# SHOTS=docs keeps one screenshot per report type there (README's "Reports" section shows them).
#   scripts/browser_check.sh            (about a minute after the release build)
set -euo pipefail
cd "$(dirname "$0")/.."
SUDO=$([ "$(id -u)" = 0 ] || echo sudo)
need() { command -v "$1" >/dev/null 2>&1; }
if ! need chromium; then $SUDO apt-get update -qq && $SUDO apt-get install -y -qq chromium >/dev/null; fi
if ! need curl || ! need jq; then $SUDO apt-get update -qq && $SUDO apt-get install -y -qq curl jq >/dev/null; fi

# The robocal binary: $ROBOCAL when set, else cargo's release build.
if [[ -n "${ROBOCAL:-}" ]]; then BIN=$(realpath "$ROBOCAL"); else
  cargo build --release --locked --quiet
  BIN=$(realpath "${CARGO_TARGET_DIR:-target}")/release/robocal
fi
tmp=$(mktemp -d)
PORT=$(python3 -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')
API=http://127.0.0.1:$PORT
"$BIN" serve --db "$tmp/robocal.db" --bind "127.0.0.1:$PORT" --workers 2 >"$tmp/server.log" 2>&1 &
SERVER=$!
cleanup() { kill "$SERVER" 2>/dev/null || true; wait "$SERVER" 2>/dev/null || true; rm -rf "$tmp"; }
trap cleanup EXIT
for _ in $(seq 100); do curl -sf "$API/readyz" >/dev/null && break; sleep 0.1; done

J='Content-Type: application/json'
call() { curl -sS --fail-with-body "$@"; }
wait_job() {
  until call "$API/v1/jobs/$1" | jq -e '.state | test("succeeded|failed|cancelled")' >/dev/null; do sleep 0.2; done
  call "$API/v1/jobs/$1"
}

echo "== the virtual cell through the service (scripts/api_walkthrough.sh)"
API=$API ROBOCAL=$BIN scripts/api_walkthrough.sh >"$tmp/walkthrough.log"
ROBOT=$(call "$API/v1/robots" | jq -r '[.[] | select(.name | startswith("cell-"))][0].id')
SET=$(call "$API/v1/robots/$ROBOT/parameter-sets" \
  | jq -r '[.[] | select((.validations | length) > 0)][0].id')
VALIDATION=$(call "$API/v1/parameter-sets/$SET" | jq -r '.validations[0].validation_id')
DIAGNOSIS=$(call "$API/v1/parameter-sets/$SET/diagnoses" | jq -r '.[0].id')

echo "== the UR10 data set: imported by the CLI, uploaded, identified on series C, validated on B, diagnosed"
"$BIN" import ur10-ipa --series ../shared/datasets/ur10-ipa/Series_C:identification \
  --series ../shared/datasets/ur10-ipa/Series_B:validation --out "$tmp/ur10.json" >/dev/null
UR10=$(call "$API/v1/robots" -H "$J" -d '{"name": "ur10-ipa", "robot": {"preset": "ur10"}}' | jq -r .id)
for k in $(seq 0 $(($(jq '.sessions | length' "$tmp/ur10.json") - 1))); do
  s=$(jq -c ".sessions[$k] | {name, purpose, instrument, tool, order} | with_entries(select(.value != null))" "$tmp/ur10.json")
  SID=$(call "$API/v1/robots/$UR10/sessions" -H "$J" -d "$s" | jq -r .id)
  jq -c "{measurements: .sessions[$k].measurements}" "$tmp/ur10.json" >"$tmp/batch.json"
  call "$API/v1/sessions/$SID/measurements" -H "$J" -d @"$tmp/batch.json" >/dev/null
done
JOB=$(call "$API/v1/robots/$UR10/identifications" -H "$J" -d '{"sessions": ["series-C"]}' | jq -r .id)
UR10_SET=$(wait_job "$JOB" | jq -r .result.parameter_set_id)
JOB=$(call "$API/v1/parameter-sets/$UR10_SET/validations" -H "$J" -d '{"sessions": ["series-B"]}' | jq -r .id)
UR10_VALIDATION=$(wait_job "$JOB" | jq -r .result.validation_id)
JOB=$(call "$API/v1/parameter-sets/$UR10_SET/diagnoses" -H "$J" -d '{"validation": []}' | jq -r .id)
UR10_DIAGNOSIS=$(wait_job "$JOB" | jq -r .result.diagnosis_id)
for id in "$UR10_SET" "$UR10_VALIDATION" "$UR10_DIAGNOSIS"; do [[ "$id" != null ]] || { echo "a UR10 job failed"; exit 1; }; done

echo "== the CLI's study (virtual cell) and crossval (UR10) reports, opened as files"
"$BIN" simulate --seed 2 --out "$tmp/sim.json" >/dev/null
"$BIN" study "$tmp/sim.json" --sizes 20,30,45 --sets 4 --report "$tmp/study.html" >/dev/null
"$BIN" crossval "$tmp/ur10.json" --session series-C --folds 3 --sizes 50,100,200 --draws 4 --transfer series-B \
  --report "$tmp/crossval.html" >/dev/null

echo "== the CLI's ISO 9283 report (UR10 series D, nominal and calibrated on series C)"
"$BIN" import ur10-ipa --series ../shared/datasets/ur10-ipa/Series_C:identification \
  --series ../shared/datasets/ur10-ipa/Series_D:validation --out "$tmp/ur10_iso.json" >/dev/null
"$BIN" identify "$tmp/ur10_iso.json" --sessions series-C --out "$tmp/ur10_iso_params.json" >/dev/null
"$BIN" iso9283 poses-ur10 ../shared/datasets/ur10-ipa/Series_D --out "$tmp/d_poses.csv" >/dev/null
"$BIN" iso9283 evaluate "$tmp/ur10_iso.json" --session series-D --poses "$tmp/d_poses.csv" \
  --params "$tmp/ur10_iso_params.json" --pairs D001:D002,D001:D004 --html "$tmp/iso9283.html" >/dev/null

# name | URL | plots expected (<svg> elements; a diagnosis: two, and one evidence plot per named
# joint effect)
checks=(
  "validation|$API/v1/validations/$VALIDATION/report|10"
  "identification|$API/v1/parameter-sets/$SET/report|$(($(call "$API/v1/parameter-sets/$SET/export" \
    | jq '[.parameters[] | select(.std != null and .nominal != null) | .unit] | unique | length') + 10))"
  "diagnosis|$API/v1/diagnoses/$DIAGNOSIS/report|$(($(call "$API/v1/diagnoses/$DIAGNOSIS" | jq '.report.evidence | length') + 2))"
  "ur10-validation|$API/v1/validations/$UR10_VALIDATION/report|8"
  "ur10-identification|$API/v1/parameter-sets/$UR10_SET/report|$(($(call "$API/v1/parameter-sets/$UR10_SET/export" \
    | jq '[.parameters[] | select(.std != null and .nominal != null) | .unit] | unique | length') + 8))"
  "ur10-diagnosis|$API/v1/diagnoses/$UR10_DIAGNOSIS/report|$(($(call "$API/v1/diagnoses/$UR10_DIAGNOSIS" | jq '.report.evidence | length') + 2))"
  "history|$API/v1/robots/$ROBOT/history/report|1"
  "study|file://$tmp/study.html|3"
  "crossval|file://$tmp/crossval.html|1"
  "iso9283|file://$tmp/iso9283.html|0"
)
chrome=(chromium --headless --no-sandbox --disable-gpu --disable-background-networking --hide-scrollbars
  --no-first-run --disable-extensions --user-data-dir="$tmp/chrome")
failed=0
for c in "${checks[@]}"; do
  IFS='|' read -r name url plots <<<"$c"
  "${chrome[@]}" --window-size=1000,2200 --screenshot="$tmp/$name.png" "$url" >/dev/null 2>"$tmp/$name.shot.log"
  "${chrome[@]}" --enable-logging=stderr --v=0 --dump-dom "$url" >"$tmp/$name.dom.html" 2>"$tmp/$name.console.log"
  if ! python3 - "$name" "$tmp/$name.png" "$tmp/$name.dom.html" "$tmp/$name.console.log" "$plots" <<'EOF'
import re, struct, sys, zlib
from html.parser import HTMLParser

name, png, dom, console, plots = sys.argv[1:6]
plots = int(plots)

def pixels(path):
    """Decode an 8-bit RGB/RGBA non-interlaced PNG (what Chromium writes): rows of pixels."""
    data = open(path, "rb").read()
    assert data[:8] == b"\x89PNG\r\n\x1a\n", "not a PNG"
    pos, idat, w = 8, b"", 0
    while pos < len(data):
        n, kind = struct.unpack(">I4s", data[pos:pos + 8])
        body = data[pos + 8:pos + 8 + n]
        if kind == b"IHDR":
            w, h, depth, colour, _, _, interlace = struct.unpack(">IIBBBBB", body)
            assert depth == 8 and colour in (2, 6) and interlace == 0, (depth, colour, interlace)
            bpp = 3 if colour == 2 else 4
        elif kind == b"IDAT":
            idat += body
        pos += 12 + n
    raw, stride, prev, rows = zlib.decompress(idat), w * bpp, bytearray(w * bpp), []
    for y in range(h):
        f, line = raw[y * (stride + 1)], bytearray(raw[y * (stride + 1) + 1:(y + 1) * (stride + 1)])
        if f == 1:
            for i in range(bpp, stride): line[i] = (line[i] + line[i - bpp]) & 255
        elif f == 2:
            for i in range(stride): line[i] = (line[i] + prev[i]) & 255
        elif f == 3:
            for i in range(stride): line[i] = (line[i] + ((line[i - bpp] if i >= bpp else 0) + prev[i]) // 2) & 255
        elif f == 4:
            for i in range(stride):
                a, b, c = (line[i - bpp] if i >= bpp else 0), prev[i], (prev[i - bpp] if i >= bpp else 0)
                p = a + b - c; pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
                line[i] = (line[i] + (a if pa <= pb and pa <= pc else b if pb <= pc else c)) & 255
        rows.append(bytes(line)); prev = line
    return w, h, bpp, rows

problems = []
w, h, bpp, rows = pixels(png)
colours, dark = set(), 0
for r in rows[::2]:
    for i in range(0, len(r), bpp * 2):
        px = r[i:i + 3]
        colours.add(px)
        dark += px != b"\xff\xff\xff"
sampled = (h // 2) * (w // 2)
non_white = dark / max(sampled, 1)
if len(colours) < 20 or non_white < 0.02:
    problems.append(f"blank screenshot: {len(colours)} colours, {non_white:.1%} non-white")

class Svgs(HTMLParser):
    def __init__(self):
        super().__init__(); self.depth = 0; self.svgs = []; self.scripts = 0
    def handle_starttag(self, tag, attrs):
        if tag == "script": self.scripts += 1
        if tag == "svg":
            if self.depth == 0: self.svgs.append({"elements": 0, "text": 0})
            self.depth += 1
        elif self.depth:
            self.svgs[-1]["elements"] += 1
            self.svgs[-1]["text"] += tag == "text"
    def handle_startendtag(self, tag, attrs):
        self.handle_starttag(tag, attrs)
        if tag == "svg": self.depth -= 1
    def handle_endtag(self, tag):
        if tag == "svg": self.depth -= 1

p = Svgs(); p.feed(open(dom, encoding="utf-8").read())
if len(p.svgs) != plots:
    problems.append(f"{len(p.svgs)} plots in the DOM, expected {plots}")
for k, s in enumerate(p.svgs):
    if s["elements"] < 15 or s["text"] < 3:
        problems.append(f"plot {k + 1} is nearly empty: {s}")
if p.scripts:
    problems.append("a <script> element")
log = open(console, encoding="utf-8", errors="replace").read()
bad = [l for l in log.splitlines() if re.search(r"CONSOLE|Uncaught|Refused to|Failed to load", l)]
if bad:
    problems.append("console: " + " | ".join(bad[:3]))
status = "FAIL" if problems else "ok"
print(f"{status:4} {name:20} {len(p.svgs)} plots, {min((s['elements'] for s in p.svgs), default=0)}+ elements each, "
      f"screenshot {w}×{h} with {len(colours)} colours, {non_white:.0%} non-white")
for m in problems:
    print("     " + m)
sys.exit(1 if problems else 0)
EOF
  then failed=1; fi
done
if [[ -n "${SHOTS:-}" ]]; then
  mkdir -p "$SHOTS"
  for t in validation identification diagnosis study crossval history; do cp "$tmp/$t.png" "$SHOTS/report-$t.png"; done
  cp "$tmp/ur10-validation.png" "$SHOTS/report-ur10-validation.png"
  echo "screenshots in $SHOTS/"
fi
exit $failed
