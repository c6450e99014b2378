// HDF5 export of a traffic log's interface data (demfdm_log export --format h5).
//
// Layout (all arrays row-major, SI units):
//   attributes /run_id, /first_step, /last_step (the requested range)
//   /mesh/point_ids [n] int64, /mesh/positions [n,3], /mesh/triangles [m,3] int32 (rows into
//        the point list), /mesh/wall_of_triangle [m] int32, attribute n_walls
//        (only when the log holds the whole interface mesh)
//   /kin/steps [s] int64, /kin/positions [s,n,3], /kin/velocities [s,n,3]
//   /force/steps [t] int64, /force/forces [t,n,3] [N], /force/stiffness [t,n] [N/m],
//        /force/total [t,3] [N]
// Only steps whose data are complete in the log are written.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>

#include "traffic_log.hpp"

namespace demfdm::traffic {

struct ExportCounts {
  bool mesh = false;
  std::size_t kin_steps = 0, force_steps = 0;
};

// Throws std::runtime_error naming what failed.
ExportCounts export_h5(const Log& log, std::int64_t first, std::int64_t last, const std::string& path);

}  // namespace demfdm::traffic
