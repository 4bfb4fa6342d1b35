#pragma once
// The paper's numbers (Massari et al., "Functional mimicry of Ruffini receptors with Fiber Bragg Gratings
// and Deep Neural Networks"), once for the whole tree: reports print them beside ours, tests and the twin's
// calibration aim at them. Units in the names.
namespace ruffini::paper {

// Receptive fields (T2) and sensitivity (T1).
inline constexpr double kHotSpotMedianMm2 = 15.9, kHotSpotQ1Mm2 = 9.0, kHotSpotQ3Mm2 = 20.9;
inline constexpr double kDetection75N = 0.0506;  // 75 % detection (von Frey, 12 subjects)

// The indentation data set and the random guess.
inline constexpr double kMedianForceN = 0.176;
inline constexpr double kRgForceErrorN = 0.194, kRgForceIqrN = 0.714;
inline constexpr double kRgLocationMm = 34.72, kRgLocationIqrMm = 24.68;

// Decoding results (test set) and effect sizes.
inline constexpr double kForceErrorMn = 35, kForceIqrMn = 56, kLocationErrorMm = 3.2, kLocationIqrMm = 2.3;
inline constexpr double kCohensDForce = 0.84, kCohensDLocation = 1.90;
inline constexpr double kForceErrorVsForceR2 = 0.97;

}  // namespace ruffini::paper
