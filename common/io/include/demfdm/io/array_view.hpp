// Typed, non-owning views of flat SoA arrays handed to the output writers.
//
// Every array the writers store is row-major [rows, cols]: one row per particle, bond, node
// or zone, `cols` components per row (3 for a vector, 6 for a symmetric tensor in VTK order
// xx, yy, zz, xy, yz, xz). A view with cols == 1 is stored as a 1-D dataset [rows], as in
// the results layout of common/io/README.md.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <stdexcept>
#include <string>
#include <string_view>
#include <type_traits>
#include <vector>

namespace demfdm::io {

/// Element types the results files hold (little-endian on disk, native in memory).
enum class DType : std::uint8_t { kFloat64, kFloat32, kInt32, kInt64, kUInt8 };

/// Bytes per element of `t`.
std::size_t dtype_size(DType t) noexcept;
/// "float64", "float32", "int32", "int64", "uint8" (for messages).
std::string_view dtype_name(DType t) noexcept;

template <class T>
inline constexpr bool kIsStorable =
    std::is_same_v<T, double> || std::is_same_v<T, float> || std::is_same_v<T, std::int32_t> ||
    std::is_same_v<T, std::int64_t> || std::is_same_v<T, std::uint8_t>;

template <class T>
constexpr DType dtype_of() noexcept {
  static_assert(kIsStorable<T>, "results arrays are double, float, int32, int64 or uint8");
  if constexpr (std::is_same_v<T, double>) return DType::kFloat64;
  else if constexpr (std::is_same_v<T, float>) return DType::kFloat32;
  else if constexpr (std::is_same_v<T, std::int32_t>) return DType::kInt32;
  else if constexpr (std::is_same_v<T, std::int64_t>) return DType::kInt64;
  else return DType::kUInt8;
}

/// A typed view of `rows * cols` contiguous elements. Does not own the data.
/// Invariant: the viewed buffer holds rows * cols elements of `dtype`.
struct ArrayView {
  DType dtype = DType::kFloat64;
  const void* data = nullptr;
  std::size_t rows = 0;
  std::size_t cols = 1;

  ArrayView() = default;

  /// View `values` as [values.size() / cols, cols]. Throws std::invalid_argument when
  /// cols is 0 or does not divide the element count.
  template <class T, std::size_t Extent>
  ArrayView(std::span<T, Extent> values, std::size_t components = 1)
      : dtype(dtype_of<std::remove_const_t<T>>()), data(values.data()), cols(components) {
    if (components == 0 || values.size() % components != 0)
      throw std::invalid_argument("ArrayView: the number of components per row must be >= 1 and divide the element count; found " +
                                  std::to_string(values.size()) + " elements with " +
                                  std::to_string(components) + " components per row");
    rows = values.size() / components;
  }
  template <class T>
  ArrayView(const std::vector<T>& values, std::size_t components = 1)
      : ArrayView(std::span<const T>(values), components) {}

  /// Number of elements (rows * cols).
  std::size_t size() const noexcept { return rows * cols; }
};

/// A named per-entity array of one frame (a ParaView point or cell array).
/// `name` is both the HDF5 dataset name and the array name shown in ParaView.
struct FieldArray {
  std::string name;
  ArrayView data;
};

}  // namespace demfdm::io
