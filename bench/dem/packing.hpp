// The reference packing of the DEM benchmarks (bench/dem/data): a LAMMPS dump, 9 header lines
// with the box bounds on lines 6-8, then "x y z radius" per ball (SI). Shared by bench_dem and
// bench_dist.
#pragma once

#include <fstream>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "demfdm/dem/vec3.hpp"

namespace demfdm::dem {

struct Packing {
  Vec3 lo, hi;
  std::vector<Vec3> x;
  std::vector<double> r;
};

inline Packing load(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw std::runtime_error("cannot open packing file '" + path + "'");
  Packing p;
  std::string line;
  for (int l = 1; l <= 9; ++l) {
    std::getline(in, line);
    if (l >= 6 && l <= 8) {
      std::istringstream s(line);
      s >> p.lo[l - 6] >> p.hi[l - 6];
    }
  }
  double x, y, z, r;
  while (in >> x >> y >> z >> r) {
    p.x.push_back({x, y, z});
    p.r.push_back(r);
  }
  return p;
}

}  // namespace demfdm::dem
