#pragma once
// Importing a CSV recording into the dataset layout.
//
// Each row: time in seconds, then 16 wavelengths in nm, then optionally force_n, or force_n, y_mm, r_deg
// (so 17, 18 or 20 columns; every row must have the same count). A first row whose first cell is not a
// number is a header and is skipped. Empty label cells mean unknown (NaN). A wrong column count or a
// non-numeric cell is an InputError naming the file, the line number and the column.
#include <string>

#include "ruffini/dataset/dataset.h"

namespace ruffini::dataset {

struct CsvImportOptions {
  std::string patch_name;
  double surface_radius_mm = 0.0;
  std::array<double, kChannels> reference_wavelength_nm{};  // usually the patch spec's nominal values
};

// The sample rate is the inverse of the median time step; serial is the row index; flags are 0;
// true_force_n is NaN; each run of consecutive rows with finite y_mm and r_deg is one indentation.
Dataset ImportCsv(const std::string& csv_path, const CsvImportOptions& options);

}  // namespace ruffini::dataset
