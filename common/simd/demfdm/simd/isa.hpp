// The instruction sets a lane kernel is compiled for (one translation unit includes its lane
// loops once per set inside `#pragma GCC target` regions) and the run-time choice among them.
// No region enables FMA and the project compiles with -ffp-contract=off, so the builds of one
// kernel give the same bits on every set.
#pragma once

namespace demfdm::simd {

enum class Isa { kBaseline, kAvx2, kAvx512 };

/// Whether this CPU runs code compiled for `isa`.
inline bool isa_available(Isa isa) {
  switch (isa) {
    case Isa::kBaseline: return true;
    case Isa::kAvx2: return __builtin_cpu_supports("avx2");
    case Isa::kAvx512:
      return __builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512dq") &&
             __builtin_cpu_supports("avx512vl");
  }
  return false;
}

/// The best instruction set of this CPU.
inline Isa best_isa() {
  static const Isa best = isa_available(Isa::kAvx512) ? Isa::kAvx512
                          : isa_available(Isa::kAvx2) ? Isa::kAvx2
                                                      : Isa::kBaseline;
  return best;
}

inline const char* isa_name(Isa isa) {
  switch (isa) {
    case Isa::kAvx2: return "avx2";
    case Isa::kAvx512: return "avx512";
    default: return "baseline";
  }
}

/// The build of one kernel for `isa`.
template <class F>
F pick(Isa isa, F base, F avx2, F avx512) {
  switch (isa) {
    case Isa::kAvx2: return avx2;
    case Isa::kAvx512: return avx512;
    default: return base;
  }
}

}  // namespace demfdm::simd
