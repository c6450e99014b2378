// Stage 2 of the vectorised ball–ball and wall passes (pair_block.hpp): the lane loops of
// pair_block_body.inc compiled for the baseline ISA, AVX2 and AVX-512, chosen at run time.
// No FMA is enabled in any region (and -ffp-contract=off forbids contraction), so the three
// builds give the same bits; tests/dem/simd_kernel_test.cpp checks this against the scalar pass.
#include "demfdm/dem/pair_block.hpp"

#include "demfdm/dem/laws/registry.hpp"

namespace demfdm::dem::pairblock {

namespace baseline {
#include "pair_block_body.inc"
}  // namespace baseline

#pragma GCC push_options
#pragma GCC target("avx2")
namespace avx2 {
#include "pair_block_body.inc"
}  // namespace avx2
#pragma GCC pop_options

#pragma GCC push_options
#pragma GCC target("avx512f,avx512dq,avx512vl")
namespace avx512 {
#include "pair_block_body.inc"
}  // namespace avx512
#pragma GCC pop_options

using simd::pick;

Fn linear_kernel(Isa isa) {
  return pick<Fn>(isa, &baseline::linear_block, &avx2::linear_block, &avx512::linear_block);
}
Fn softbond_kernel(Isa isa) {
  return pick<Fn>(isa, &baseline::softbond_block, &avx2::softbond_block, &avx512::softbond_block);
}
Fn hertz_kernel(Isa isa) {
  return pick<Fn>(isa, &baseline::hertz_block, &avx2::hertz_block, &avx512::hertz_block);
}
Fn pbond_kernel(Isa isa) {
  return pick<Fn>(isa, &baseline::pbond_block, &avx2::pbond_block, &avx512::pbond_block);
}
WallFn linear_wall_kernel(Isa isa) {
  return pick<WallFn>(isa, &baseline::linear_wall_block, &avx2::linear_wall_block, &avx512::linear_wall_block);
}
WallFn hertz_wall_kernel(Isa isa) {
  return pick<WallFn>(isa, &baseline::hertz_wall_block, &avx2::hertz_wall_block, &avx512::hertz_wall_block);
}
WallFn softbond_wall_kernel(Isa isa) {
  return pick<WallFn>(isa, &baseline::softbond_wall_block, &avx2::softbond_wall_block, &avx512::softbond_wall_block);
}
WallFn pbond_wall_kernel(Isa isa) {
  return pick<WallFn>(isa, &baseline::pbond_wall_block, &avx2::pbond_wall_block, &avx512::pbond_wall_block);
}
MotionFn motion_kernel(Isa isa) {
  return pick<MotionFn>(isa, &baseline::motion_block, &avx2::motion_block, &avx512::motion_block);
}

}  // namespace demfdm::dem::pairblock
