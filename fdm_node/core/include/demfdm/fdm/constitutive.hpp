// Constitutive updates per tetrahedron, small-strain increments (docs/theory.md 5.4).
// Stateless inline functions over small constant structs: the zone kernels, the element tests
// and the unit tests all call these same functions.
//
// Stress and strain are symmetric tensors stored as (xx, yy, zz, xy, yz, xz), tension
// positive; strain increments are tensor (not engineering) shear components.
#pragma once

#include <array>
#include <cmath>
#include <cstdint>
#include <limits>

#include "demfdm/fdm/params.hpp"

namespace demfdm::fdm {

// Plastic state bits per zone (docs/theory.md 5.4: "shear now / tension now / past").
enum PlasticState : std::uint8_t {
  kShearNow = 1,
  kTensionNow = 2,
  kShearPast = 4,
  kTensionPast = 8,
};

// Derived constants of one material (docs/theory.md 5.4).
struct MaterialConstants {
  double bulk = 0.0;       // [Pa] K = E / (3(1-2 nu))
  double shear = 0.0;      // [Pa] G = E / (2(1+nu))
  double alpha1 = 0.0;     // [Pa] K + 4G/3
  double alpha2 = 0.0;     // [Pa] K - 2G/3
  double density = 0.0;    // [kg/m^3]
  // Mohr-Coulomb only:
  double cohesion = 0.0;   // [Pa] c
  double n_phi = 1.0;      // [-] (1+sin phi)/(1-sin phi)
  double n_psi = 1.0;      // [-] (1+sin psi)/(1-sin psi)
  double sqrt_n_phi = 1.0; // [-]
  double tension = 0.0;    // [Pa] sigma^t, limited to the apex c/tan(phi) (+inf if phi = 0)
  double alpha_p = 0.0;    // [-] sqrt(1+N_phi^2) + N_phi
  double sigma_p = 0.0;    // [Pa] sigma^t N_phi - 2c sqrt(N_phi)
};

MaterialConstants make_constants(const Material& m);

// Linear elastic increment: sigma += 2G de + (K - 2G/3) tr(de) I.
inline void elastic_update(const MaterialConstants& m, const double* de, double* s) {
  const double tr = de[0] + de[1] + de[2];
  const double two_g = 2.0 * m.shear;
  const double lam = m.alpha2 * tr;
  s[0] += two_g * de[0] + lam;
  s[1] += two_g * de[1] + lam;
  s[2] += two_g * de[2] + lam;
  s[3] += two_g * de[3];
  s[4] += two_g * de[4];
  s[5] += two_g * de[5];
}

// Eigen-decomposition of a symmetric 3x3 tensor by cyclic Jacobi rotations (deterministic,
// accurate for repeated eigenvalues). Eigenvalues ascending in `val`; `vec[k]` is the unit
// eigenvector of val[k].
void symmetric_eigen(const double* s, std::array<double, 3>& val, std::array<std::array<double, 3>, 3>& vec);

// Same result, faster: the closed-form eigenvalue farthest from the other two gives an accurate
// eigenvector (cross products of the rows of A - lambda I); the other two come from an exact
// 2x2 diagonalisation in the orthogonal plane; all eigenvalues are Rayleigh quotients. Near-
// isotropic tensors fall back to Jacobi. Used by the Mohr-Coulomb return.
void symmetric_eigen_fast(const double* s, std::array<double, 3>& val, std::array<std::array<double, 3>, 3>& vec);

// Principal values only, ascending (closed form, for the cheap elastic check).
std::array<double, 3> principal_values(const double* s);

// Mohr-Coulomb with tension cut-off (FLAC3D form, docs/theory.md 5.4): elastic trial, then
// return in principal space, eigenvectors unchanged. Returns kShearNow / kTensionNow / 0.
// Shear return: the docs/theory.md 5.4 rule; if it reverses the order of sigma2 and sigma3
// (triaxial-compression edge) or of sigma1 and sigma2 (triaxial-extension edge), the return is
// redone with both planes active (same flow rule on each), so edge states end on the surface.
// Tension return: the docs/theory.md 5.4 rule on sigma3; if sigma2 (then sigma1) still exceeds
// sigma^t after it, the same associated rule is applied jointly to those directions (the
// corner and apex of the cut-off), so a hydrostatic tension state maps to sigma^t I.
std::uint8_t mohr_coulomb_return(const MaterialConstants& m, double* s);

inline std::uint8_t mohr_coulomb_update(const MaterialConstants& m, const double* de, double* s) {
  elastic_update(m, de, s);
  return mohr_coulomb_return(m, s);
}

}  // namespace demfdm::fdm
