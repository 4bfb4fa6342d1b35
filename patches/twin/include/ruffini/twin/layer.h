#pragma once
// Linear elasticity of the silicone cover: a layer of thickness h bonded to a rigid limb (no displacement
// at z = h), loaded on its free surface (z = 0) by an axisymmetric normal pressure of total force 1 N.
//
// Derivation (docs/twin.md has the long form). With Love's strain function phi(r, z), biharmonic, the
// axisymmetric fields are 2G u_r = -d2phi/drdz, 2G u_z = 2(1-nu) lap(phi) - d2phi/dz2,
// s_zz = d/dz[(2-nu) lap(phi) - d2phi/dz2], s_rz = d/dr[(1-nu) lap(phi) - d2phi/dz2].
// A Hankel mode phi = f(z) J0(k r) is biharmonic for f in span{e^-kz, kz e^-kz, e^-k(h-z), k(h-z) e^-k(h-z)}
// (the growing exponentials written from the bottom so nothing overflows). Per wavenumber k the four
// boundary conditions — s_zz(0) = -p(k), s_rz(0) = 0, u_r(h) = 0, u_z(h) = 0 — fix the four coefficients
// (a 4x4 solve). The surface pressure enters only through its Hankel transform p(k): F/2pi for a point
// load, F/2pi * 3 (sin ka - ka cos ka)/(ka)^3 for a Hertzian contact of radius a. Then at depth z
//   u_r(r) = int_0^inf U(k) J1(k r) k dk,  U(k) = k f'(z) / 2G,
//   eps_tt = u_r / r,  eps_rr = du_r/dr = int U(k) k^2 J0(k r) dk - u_r / r,
// integrated numerically (midpoint rule) on a wavenumber grid fine enough for r up to r_max.
// In the half-space limit (h >> depth) this reproduces Boussinesq's solution (tested).
#include <vector>

namespace ruffini::twin {

struct LayerParams {
  double thickness_mm = 8.0;
  double depth_mm = 4.0;            // where the strain is read (the fibre)
  double youngs_modulus_kpa = 152.0;
  double poisson_ratio = 0.49;
};

// In-plane strain at the read depth as radial profiles, per newton of total load.
struct StrainProfile {
  double dr_mm = 0.1;
  std::vector<double> eps_rr;  // radial normal strain at r = i * dr_mm
  std::vector<double> eps_tt;  // hoop normal strain
  // Linear interpolation; 0 beyond the last sample.
  [[nodiscard]] double Rr(double r_mm) const noexcept;
  [[nodiscard]] double Tt(double r_mm) const noexcept;
};

// One profile per contact radius (0 = point load), sharing the Bessel tables.
std::vector<StrainProfile> ComputeStrainProfiles(const LayerParams& layer, const std::vector<double>& contact_radii_mm,
                                                 double r_max_mm, double dr_mm);

// Bessel functions J0(x), J1(x) (Abramowitz & Stegun 9.4, |error| < 1e-7).
void BesselJ01(double x, double& j0, double& j1) noexcept;

// Boussinesq (elastic half-space, point load F = 1 N) strains at depth z and radius r, for tests.
struct BoussinesqStrain {
  double eps_rr, eps_tt;
};
BoussinesqStrain Boussinesq(double youngs_modulus_kpa, double poisson_ratio, double z_mm, double r_mm);

}  // namespace ruffini::twin
