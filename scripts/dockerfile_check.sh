#!/usr/bin/env bash
# Does the Dockerfile's build stage copy enough to build? No container engine runs on this machine
# class, so this replays the stage's COPY lines into an empty directory and asks cargo there:
#
#   scripts/dockerfile_check.sh          cargo metadata --locked (every manifest and
#                                        target the workspace names is present; seconds; in CI)
#   scripts/dockerfile_check.sh --build  the stage's own `cargo build --release --locked --bin
#                                        robocal` there (a cold release build: minutes)
#
# It caught the workspace split (issue 28): the image copied src/ but not crates/, and cargo
# refuses a workspace whose member manifests are missing. Only plain `COPY <src>... <dest>` lines
# of the first stage are replayed (no --from, no globs), which is what the Dockerfile uses.
set -euo pipefail
cd "$(dirname "$0")/.."
mode=${1:-metadata}
ctx=$(mktemp -d)
trap 'rm -rf "$ctx"' EXIT

in_build=0
while read -r word rest; do
  case "$word" in
    FROM) if [ $in_build = 1 ]; then break; fi; in_build=1 ;;
    COPY)
      case "$rest" in --*) echo "dockerfile_check: unsupported COPY form: COPY $rest" >&2; exit 2 ;; esac
      read -r -a parts <<<"$rest"
      dest=${parts[-1]}
      unset 'parts[-1]'
      for src in "${parts[@]}"; do
        if [ ! -e "$src" ]; then echo "dockerfile_check: COPY source '$src' does not exist" >&2; exit 1; fi
        if [ "${dest%/}" = "." ]; then target="$ctx/$(basename "$src")"; else target="$ctx/${dest#./}"; fi
        mkdir -p "$(dirname "$target")"
        # The context as .dockerignore leaves it: no build directory, no caches.
        tar -C "$(dirname "$src")" --exclude=target --exclude=__pycache__ -cf - "$(basename "$src")" \
          | tar -C "$(dirname "$target")" -xf -
        if [ "$(basename "$src")" != "$(basename "$target")" ]; then mv "$(dirname "$target")/$(basename "$src")" "$target"; fi
      done ;;
  esac
done < <(grep -E '^(FROM|COPY) ' Dockerfile)

cd "$ctx"
case "$mode" in
  metadata) cargo metadata --locked --format-version 1 >/dev/null
            echo "dockerfile_check: the build stage's context is a complete workspace" ;;
  --build) CARGO_TARGET_DIR="$ctx/target" cargo build --release --locked --bin robocal
           "$ctx/target/release/robocal" --version
           echo "dockerfile_check: the build stage's context builds the binary" ;;
  *) echo "usage: $0 [--build]" >&2; exit 2 ;;
esac
