#!/bin/bash
# Review 12, finding 4 (static): the map's binding covers the model file (model_sha256) and the twin's spec/cast/edges
# (measured_on), not the decoder service's runtime configuration. `ruffini sensitivity` always measures with
# link::DecoderChoice{} (paper-float) and the default PipelineConfig; ruffini-decoder takes --decoder <GRID>-float,
# --rate-hz, --retare-force-n, --max-frozen-s..., and the aggregator compares the hello's decoder_config only when the
# scene pins safety.decoders.config_sha256, which no shipped scene does. Exit 1 while it holds.
R=$(cd "$(dirname "$0")/../.." && pwd); repro=0
grep -q 'link::DecoderChoice{}' "$R/services/ruffini/cmd_coverage.cpp" && echo "sensitivity measures with DecoderChoice{} (paper-float) only" && repro=1
"$R/build/release/bin/ruffini-decoder" --help 2>&1 | grep -q -- '--decoder TEXT=paper-float' && echo "ruffini-decoder accepts --decoder (paper / one grid, float / double)"
n=$(grep -l 'config_sha256' "$R"/config/scenes/*.yaml 2>/dev/null | wc -l); echo "shipped scenes pinning decoders.config_sha256: $n"
[ "$n" = 0 ] || repro=0
grep -q 'decoder_config\|DecoderChoice' "$R/patches/sim/src/scenario.cpp" "$R/services/aggregator/scene_setup.cpp" && repro=0
[ $repro = 1 ] && { echo "REPRODUCES"; exit 1; }; echo "fixed"; exit 0
