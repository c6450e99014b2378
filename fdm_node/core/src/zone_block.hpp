// The zone pass on vector lanes: kLanes zones at once, one per lane, for the elastic law in
// small strain with the stresses updated (the default continuum's every step). The lane loops
// (zone_block_body.inc) are compiled for the baseline ISA, AVX2 and AVX-512 and chosen at run
// time; each lane runs zone::zone_body, so they give the scalar kernel's bits
// (tests/fdm/zone_block_test.cpp).
#pragma once

#include <cstdint>

#include "demfdm/simd/isa.hpp"
#include "zone_body.hpp"

namespace demfdm::fdm::zone {

inline constexpr int kLanes = 8;

/// kLanes distinct zones of one law's list.
using Fn = void (*)(const Ctx&, const std::int32_t* zones);

/// The elastic small-strain kernel, volumetric averaging per zone (zone_avg) or per overlay.
Fn elastic_kernel(simd::Isa isa, bool zone_avg);

}  // namespace demfdm::fdm::zone
