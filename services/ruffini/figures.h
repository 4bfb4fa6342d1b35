#pragma once
// Pictures for the twin report: hot-spot maps per grating and the detection curve.
#include <string>
#include <vector>

#include "ruffini/twin/report.h"

namespace ruffini::cli {

// Writes hotspot_fbgNN.svg for every grating and hotspots_all.svg; returns the paths written.
std::vector<std::string> WriteHotSpotFigures(const twin::SkinTwin& twin, const twin::HotSpotMaps& maps,
                                             const twin::TwinReport& report, double hot_spot_force_n,
                                             const std::string& dir);
// Writes detection_curve.svg; returns its path.
std::string WriteDetectionFigure(const twin::TwinReport& report, const std::string& dir);

}  // namespace ruffini::cli
