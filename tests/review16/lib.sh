# Review 16 helpers (sourced). ROOT: the repository; B: its build's bin; OUT: scratch (never inside the repository).
ROOT=${ROOT:-$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)}
B=${B:-$ROOT/build/release/bin}
OUT=${OUT:-/tmp/review16}
mkdir -p "$OUT"
# The model file as protobuf text (the file: 8-byte magic, 8-byte size, payload, 4-byte FNV-1a).
rmodel_text() { local f=$1 s; s=$(stat -c %s "$f"); tail -c +17 "$f" | head -c $((s - 20)) |
  (cd "$ROOT/proto" && protoc -I. --decode=ruffini.v1.DecoderModel ruffini/v1/model.proto); }
# The response map's section of a model file.
rmodel_response() { rmodel_text "$1" | awk '/^response \{/{p=1} p{print} p&&/^\}/{exit}'; }
# Two copies of config/: $OUT/old (the upper arms' files before 6d63c0f) and $OUT/new (as committed), so that each
# scene copy names its own files (the scene's model paths are relative).
make_configs() {
  [ -f "$OUT/old/.done" ] && [ -f "$OUT/new/.done" ] && return
  rm -rf "$OUT/old" "$OUT/new"; cp -r "$ROOT/config" "$OUT/old"; cp -r "$ROOT/config" "$OUT/new"
  for p in a b; do git -C "$ROOT" show 6d63c0f~1:config/models/cobot-field-upper_arm_$p.rmodel > "$OUT/old/models/cobot-field-upper_arm_$p.rmodel"
                   git -C "$ROOT" show 6d63c0f:config/models/cobot-field-upper_arm_$p.rmodel > "$OUT/new/models/cobot-field-upper_arm_$p.rmodel"; done
  touch "$OUT/old/.done" "$OUT/new/.done"
}
