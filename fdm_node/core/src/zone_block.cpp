// The zone pass's lane loops for the baseline ISA, AVX2 and AVX-512 (zone_block.hpp).
#include "zone_block.hpp"

namespace demfdm::fdm::zone {

namespace baseline {
#include "zone_block_body.inc"
}  // namespace baseline

#pragma GCC push_options
#pragma GCC target("avx2")
namespace avx2 {
#include "zone_block_body.inc"
}  // namespace avx2
#pragma GCC pop_options

#pragma GCC push_options
#pragma GCC target("avx512f,avx512dq,avx512vl")
namespace avx512 {
#include "zone_block_body.inc"
}  // namespace avx512
#pragma GCC pop_options

Fn elastic_kernel(simd::Isa isa, bool zone_avg) {
  return zone_avg ? simd::pick<Fn>(isa, &baseline::elastic_zone_avg, &avx2::elastic_zone_avg, &avx512::elastic_zone_avg)
                  : simd::pick<Fn>(isa, &baseline::elastic_overlay_avg, &avx2::elastic_overlay_avg,
                                   &avx512::elastic_overlay_avg);
}

}  // namespace demfdm::fdm::zone
