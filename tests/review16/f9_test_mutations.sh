#!/bin/bash
# Review 16, finding 9: TwoTouches.TheFieldScenesUpperArmsCheckForTwoTouchesToo with the repository's config/
# replaced, for the test process only (a private mount namespace: unshare -m, mount --bind; needs root; no file
# is changed), by (1) config/ before 6d63c0f (the old upper-arm files): must FAIL; (2) the new decoders carrying
# the OLD sensitivity maps (a map bound to another decoder, which no scene may use): the test PASSES, and
# `ruffini check-scene` (ctest cli.check_scene_cobot_field) is what refuses it. Exit 1 when (1) passes or (2)'s
# check-scene accepts the scene.
set -u; . "$(dirname "$0")/lib.sh"; make_configs
T="$B/two_touch_test --gtest_filter=TwoTouches.TheFieldScenesUpperArmsCheckForTwoTouchesToo"
# (2): the new files with the old files' sensitivity section (protobuf text surgery, re-encoded)
rm -rf $OUT/mix; cp -r $OUT/new $OUT/mix
for p in a b; do python3 - $OUT/old/models/cobot-field-upper_arm_$p.rmodel $OUT/new/models/cobot-field-upper_arm_$p.rmodel \
    $OUT/mix/models/cobot-field-upper_arm_$p.rmodel "$ROOT/proto" <<'PY'
import struct, subprocess, sys
old, new, out, proto = sys.argv[1:5]
def text(path):
    b = open(path, "rb").read(); n = struct.unpack("<Q", b[8:16])[0]
    return subprocess.run(["protoc", "-I.", "--decode=ruffini.v1.DecoderModel", "ruffini/v1/model.proto"], input=b[16:16 + n],
                          capture_output=True, cwd=proto, check=True).stdout.decode()
def sections(t):
    out = []
    for l in t.splitlines(keepends=True):
        if not l.startswith((" ", "}")): out.append([l.split()[0].rstrip(":"), l])
        else: out[-1][1] += l
    return out
def fnv(b):
    h = 0x811c9dc5
    for c in b: h = ((h ^ c) * 0x01000193) & 0xffffffff
    return h
osens = [t for k, t in sections(text(old)) if k == "sensitivity"][0]
mixed = "".join(osens if k == "sensitivity" else t for k, t in sections(text(new)))
p = subprocess.run(["protoc", "-I.", "--encode=ruffini.v1.DecoderModel", "ruffini/v1/model.proto"], input=mixed.encode(),
                   capture_output=True, cwd=proto, check=True).stdout
open(out, "wb").write(b"RFNMODL1" + struct.pack("<Q", len(p)) + p + struct.pack("<I", fnv(p)))
PY
done
run() { unshare -m sh -c "mount --bind $1 $ROOT/config && cd $OUT && $T" > $OUT/f9-$2.log 2>&1; }
bad=0
run $OUT/old old; r1=$?; echo "(1) old upper-arm files: test exit $r1 ($(grep -c 'Failure' $OUT/f9-old.log) failures)"; [ $r1 -eq 0 ] && bad=1
run $OUT/mix mix; r2=$?; echo "(2) new decoders, old sensitivity maps: test exit $r2"
$B/ruffini check-scene $OUT/mix/scenes/cobot-field.yaml > $OUT/f9-mix-check.log 2>&1; r3=$?
echo "    check-scene on (2): exit $r3: $(grep -o 'refused: region .upper_arm.[^;]*' $OUT/f9-mix-check.log | head -1)"
[ $r3 -eq 0 ] && bad=1
[ $bad -eq 1 ] && { echo PROBLEM; exit 1; }; echo "ok (the test needs check-scene beside it for the maps' binding)"; exit 0
