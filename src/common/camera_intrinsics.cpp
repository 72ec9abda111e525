#include "slamd/common/camera_intrinsics.hpp"

#include <cmath>
#include <sstream>

namespace slamd {

CameraIntrinsics CameraIntrinsics::scaled(int new_width, int new_height) const {
  const double sx = static_cast<double>(new_width) / width;
  const double sy = static_cast<double>(new_height) / height;
  CameraIntrinsics out = *this;
  out.width = new_width;
  out.height = new_height;
  out.fx = fx * sx;
  out.fy = fy * sy;
  // Pixel centres: continuous coordinate x maps to (x + 0.5) * s - 0.5.
  out.cx = (cx + 0.5) * sx - 0.5;
  out.cy = (cy + 0.5) * sy - 0.5;
  return out;
}

Eigen::Matrix3d CameraIntrinsics::matrix() const {
  Eigen::Matrix3d K;
  K << fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0;
  return K;
}

std::string CameraIntrinsics::validationError() const {
  std::ostringstream out;
  if (!(width > 0 && height > 0 && width <= 16384 && height <= 16384)) {
    out << "image size " << width << "x" << height << " is not in 1..16384";
  } else if (!(std::isfinite(fx) && std::isfinite(fy) && fx > 0.0 && fy > 0.0)) {
    out << "focal lengths fx=" << fx << " fy=" << fy << " must be positive and finite";
  } else if (!(std::isfinite(cx) && std::isfinite(cy))) {
    out << "principal point cx=" << cx << " cy=" << cy << " must be finite";
  } else {
    for (double d : distortion) {
      if (!std::isfinite(d)) {
        out << "distortion coefficients must be finite";
        break;
      }
    }
  }
  return out.str();
}

bool CameraIntrinsics::operator==(const CameraIntrinsics& o) const {
  return fx == o.fx && fy == o.fy && cx == o.cx && cy == o.cy && width == o.width &&
         height == o.height && distortion_model == o.distortion_model && distortion == o.distortion;
}

}  // namespace slamd
