// An HDF5 object that closes itself, and the reason HDF5 gives for an error.
#pragma once

#include <hdf5.h>

#include <string>

namespace arena::hdf5 {

// The innermost message of HDF5's error stack (where the error was found,
// e.g. "truncated file: eof = ..."), for a reason a person can act on; clears
// the stack.
inline std::string Reason() {
  std::string reason;
  H5Ewalk2(
      H5E_DEFAULT, H5E_WALK_UPWARD,
      [](unsigned n, const H5E_error2_t* e, void* out) -> herr_t {
        if (n == 0 && e->desc) *static_cast<std::string*>(out) = e->desc;
        return 0;
      },
      &reason);
  H5Eclear2(H5E_DEFAULT);
  return reason.empty() ? "HDF5 error" : reason;
}

// Closes an HDF5 object (with its kind's close function) when it goes out of scope.
struct Handle {
  hid_t id = -1;
  herr_t (*close)(hid_t) = nullptr;
  Handle(hid_t i, herr_t (*c)(hid_t)) : id(i), close(c) {}
  ~Handle() {
    if (id >= 0) close(id);
  }
  Handle(const Handle&) = delete;
  Handle& operator=(const Handle&) = delete;
};

}  // namespace arena::hdf5
