#pragma once
// The decoder's rest file (ServiceConfig::rest_file; review 10, finding 1): the baseline a patch last had at
// rest, so a restarted decoder can tell its start-up capture from a press held through the restart.
//
//   ruffini-rest 1
//   patch forearm_a
//   unix_s 1795834301
//   wavelength_nm 1530.001234 1533.998765 ... (16 values; nan for a grating that was missing)
//
// Plain text, so an operator can read what the decoder will hold it to. Hand-written: four lines, and no
// library the project has reads them more plainly.
#include <cstdint>
#include <string>

#include "ruffini/frame.h"
#include "ruffini/patch/spec.h"

namespace ruffini::decoder {

struct RestFile {
  std::string patch;
  std::int64_t unix_s = 0;
  Wavelengths wavelength_nm{};
};

// Throws InputError naming the file and what is wrong: unreadable, another format or version, another patch,
// not 16 values, a value that is neither a wavelength inside the grating's band nor nan, fewer than 9 present.
RestFile ReadRestFile(const std::string& path, const std::string& patch, const patch::PatchSpec& spec);
// Writes path.tmp, then renames it over path. Throws InputError when it cannot.
void WriteRestFile(const std::string& path, const std::string& patch, const Wavelengths& wavelength_nm);
std::int64_t UnixNowS();

}  // namespace ruffini::decoder
