#pragma once
// Writing a bench result (ruffini/eval/bench.h): the Markdown table, the Eigen-vs-libtorch ratios, bench.md
// and the speed/accuracy figure.
#include <string>

#include "ruffini/eval/bench.h"

namespace ruffini::eval {

// The table, one row per configuration (numbered from 1, as the figure's markers are).
std::string BenchTable(const BenchResult& result);
// One line per model: Eigen runtime vs the fastest libtorch configuration, gated and ungated p50.
std::string BenchRatios(const BenchResult& result);
// DIR/bench.md (how it was measured, `command` to reproduce it, the table, the ratios) and DIR/pareto.svg
// (gated p50 against location error). Throws InputError when DIR cannot be written.
void WriteBench(const BenchResult& result, const std::string& dir, const std::string& command);

}  // namespace ruffini::eval
