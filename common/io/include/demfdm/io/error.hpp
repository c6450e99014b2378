// Error type of the output library.
#pragma once

#include <stdexcept>
#include <string>

namespace demfdm::io {

/// An output operation failed. The message names the file and the call that failed (an
/// HDF5 function such as "H5Dcreate2", or a C library call such as "fopen"), followed by
/// the library's own explanation when it gave one.
class IoError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

}  // namespace demfdm::io
