#include "h5_export.hpp"

#include <hdf5.h>

#include <stdexcept>

namespace demfdm::traffic {

namespace {

// Owns one HDF5 id; closes it with its own close function.
class Id {
 public:
  Id(hid_t id, herr_t (*close)(hid_t), const std::string& what) : id_(id), close_(close) {
    if (id_ < 0) throw std::runtime_error("HDF5: " + what + " failed");
  }
  ~Id() {
    if (id_ >= 0) close_(id_);
  }
  Id(const Id&) = delete;
  Id& operator=(const Id&) = delete;
  operator hid_t() const { return id_; }

 private:
  hid_t id_;
  herr_t (*close_)(hid_t);
};

template <class T> hid_t h5_type();
template <> hid_t h5_type<double>() { return H5T_NATIVE_DOUBLE; }
template <> hid_t h5_type<std::int64_t>() { return H5T_NATIVE_INT64; }
template <> hid_t h5_type<std::int32_t>() { return H5T_NATIVE_INT32; }

template <class T>
void dataset(hid_t loc, const std::string& name, const std::vector<hsize_t>& dims, const std::vector<T>& v) {
  hsize_t n = 1;
  for (auto d : dims) n *= d;
  if (n != v.size()) throw std::logic_error("h5 export: " + name + " has the wrong size");
  Id space(H5Screate_simple(static_cast<int>(dims.size()), dims.data(), nullptr), H5Sclose, "dataspace of " + name);
  Id ds(H5Dcreate2(loc, name.c_str(), h5_type<T>(), space, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT), H5Dclose,
        "creating " + name);
  if (n > 0 && H5Dwrite(ds, h5_type<T>(), H5S_ALL, H5S_ALL, H5P_DEFAULT, v.data()) < 0)
    throw std::runtime_error("HDF5: writing " + name + " failed");
}

void attribute(hid_t loc, const std::string& name, std::int64_t value) {
  Id space(H5Screate(H5S_SCALAR), H5Sclose, "scalar dataspace");
  Id a(H5Acreate2(loc, name.c_str(), H5T_NATIVE_INT64, space, H5P_DEFAULT, H5P_DEFAULT), H5Aclose,
       "attribute " + name);
  if (H5Awrite(a, H5T_NATIVE_INT64, &value) < 0) throw std::runtime_error("HDF5: writing attribute " + name);
}

// The complete entries of a per-step map (log.kin, log.force) with first <= step <= last.
template <class Map>
std::vector<std::pair<std::int64_t, const typename Map::mapped_type*>> complete_steps(const Map& m, std::int64_t first,
                                                                                      std::int64_t last) {
  std::vector<std::pair<std::int64_t, const typename Map::mapped_type*>> out;
  for (auto it = m.lower_bound(first); it != m.end() && it->first <= last; ++it)
    if (it->second.complete()) out.emplace_back(it->first, &it->second);
  return out;
}

}  // namespace

ExportCounts export_h5(const Log& log, std::int64_t a, std::int64_t b, const std::string& path) {
  H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);  // one error message instead of HDF5's stack dump
  Id file(H5Fcreate(path.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT), H5Fclose, "creating " + path);
  attribute(file, "run_id", log.run_id);
  attribute(file, "first_step", a);
  attribute(file, "last_step", b);
  ExportCounts c;
  const auto& m = log.mesh;
  if (m.complete()) {
    Id g(H5Gcreate2(file, "mesh", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT), H5Gclose, "group mesh");
    const hsize_t np = m.point_ids.size(), nt = m.wall_of_triangle.size();
    dataset(g, "point_ids", {np}, m.point_ids);
    dataset(g, "positions", {np, 3}, m.positions);
    dataset(g, "triangles", {nt, 3}, m.triangles);
    dataset(g, "wall_of_triangle", {nt}, m.wall_of_triangle);
    attribute(g, "n_walls", m.n_walls);
    c.mesh = true;
  }
  {
    std::vector<std::int64_t> steps;
    std::vector<double> x, v;
    hsize_t np = 0;
    for (auto [k, d] : complete_steps(log.kin, a, b)) {
      np = d->positions.size() / 3;
      steps.push_back(k);
      x.insert(x.end(), d->positions.begin(), d->positions.end());
      v.insert(v.end(), d->velocities.begin(), d->velocities.end());
    }
    Id g(H5Gcreate2(file, "kin", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT), H5Gclose, "group kin");
    const hsize_t ns = steps.size();
    dataset(g, "steps", {ns}, steps);
    dataset(g, "positions", {ns, np, 3}, x);
    dataset(g, "velocities", {ns, np, 3}, v);
    c.kin_steps = steps.size();
  }
  {
    std::vector<std::int64_t> steps;
    std::vector<double> f, k, total;
    hsize_t np = 0;
    for (auto [step, d] : complete_steps(log.force, a, b)) {
      np = d->stiffness.size();
      steps.push_back(step);
      f.insert(f.end(), d->forces.begin(), d->forces.end());
      k.insert(k.end(), d->stiffness.begin(), d->stiffness.end());
      total.insert(total.end(), d->total.begin(), d->total.end());
    }
    Id g(H5Gcreate2(file, "force", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT), H5Gclose, "group force");
    const hsize_t ns = steps.size();
    dataset(g, "steps", {ns}, steps);
    dataset(g, "forces", {ns, np, 3}, f);
    dataset(g, "stiffness", {ns, np}, k);
    dataset(g, "total", {ns, 3}, total);
    c.force_steps = steps.size();
  }
  if (H5Fflush(file, H5F_SCOPE_GLOBAL) < 0) throw std::runtime_error("HDF5: flushing " + path + " failed");
  return c;
}

}  // namespace demfdm::traffic
