#pragma once
// Loading, validating and saving PatchSpec as YAML. Errors are ruffini::InputError with messages like
//   config/patches/forearm.yaml:12:3: 'gratings[4].wavelength_nm' (1512.0) must lie inside 1510..1590
#include <string>

#include "ruffini/patch/spec.h"

namespace ruffini::patch {

// Loads and validates; throws ruffini::InputError naming file:line:col, the key and what was expected.
PatchSpec LoadPatchSpec(const std::string& path);
PatchSpec ParsePatchSpec(const std::string& yaml_text, const std::string& source_name);

// Validates an in-memory spec (the loader calls it too); throws InputError naming the key.
void ValidatePatchSpec(const PatchSpec& spec);

// Writes a spec back as YAML that ParsePatchSpec reads to an equal spec.
std::string DumpPatchSpec(const PatchSpec& spec);

}  // namespace ruffini::patch
