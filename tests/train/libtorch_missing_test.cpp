// Built only when libtorch is missing at configure time: the libtorch tests show up as skipped, with the
// reason, instead of vanishing from the test list.
#include <gtest/gtest.h>

TEST(LibtorchMissing, TrainTestsNotBuilt) {
  GTEST_SKIP() << "libtorch was not found at configure time: train_test (training, golden vectors, eager and frozen "
                  "TorchScript decoders) and the cli.decoders_* tests were not built. Install libtorch-dev "
                  "(deploy/install-deps.sh) and reconfigure.";
}
