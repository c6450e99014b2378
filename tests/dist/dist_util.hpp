// Shared by the DEM-on-ranks tests (tests/dist): the rank of this process, bit comparison, and
// one verdict for every rank (rank 0 compares with its reference World; the others learn the
// result, so that every rank passes or fails together).
#pragma once

#include <gtest/gtest.h>
#include <mpi.h>

#include <cstring>
#include <vector>

#include "demfdm/dem/vec3.hpp"

namespace demfdm::dem::test {

inline int g_rank = 0, g_size = 1;

template <class T>
bool same_bits(const std::vector<T>& a, const std::vector<T>& b) {
  return a.size() == b.size() && (a.empty() || std::memcmp(a.data(), b.data(), a.size() * sizeof(T)) == 0);
}

/// Call on every rank after rank 0 has run its EXPECTs.
inline void share_verdict() {
  int ok = g_rank == 0 ? !::testing::Test::HasFailure() : 1;
  MPI_Bcast(&ok, 1, MPI_INT, 0, MPI_COMM_WORLD);
  if (g_rank != 0) {
    EXPECT_TRUE(ok) << "rank 0 found a difference";
  }
}

}  // namespace demfdm::dem::test
