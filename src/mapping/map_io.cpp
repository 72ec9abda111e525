#include "slamd/mapping/map_io.hpp"

#include <filesystem>
#include <fstream>
#include <sstream>

#include <opencv2/imgcodecs.hpp>

namespace slamd {

namespace {

bool fail(std::string* error, const std::string& text) {
  if (error) *error = text;
  return false;
}

}  // namespace

bool writePly(std::ostream& out, const PointCloud& cloud, PlyFormat format) {
  const bool with_color = cloud.colors_bgr.size() == cloud.points.size() && cloud.hasColor();
  out << "ply\nformat " << (format == PlyFormat::kBinary ? "binary_little_endian" : "ascii")
      << " 1.0\ncomment slamd map export, metres\nelement vertex " << cloud.points.size()
      << "\nproperty float x\nproperty float y\nproperty float z\n"
         "property uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n";
  for (std::size_t i = 0; i < cloud.points.size(); ++i) {
    const Eigen::Vector3f& p = cloud.points[i];
    const ColorBgr c = with_color ? cloud.colors_bgr[i] : ColorBgr{255, 255, 255};
    if (format == PlyFormat::kBinary) {
      // x86-64 is little-endian, the byte order the header declares.
      const float xyz[3] = {p.x(), p.y(), p.z()};
      const unsigned char rgb[3] = {c[2], c[1], c[0]};
      out.write(reinterpret_cast<const char*>(xyz), sizeof(xyz));
      out.write(reinterpret_cast<const char*>(rgb), sizeof(rgb));
    } else {
      out << p.x() << ' ' << p.y() << ' ' << p.z() << ' ' << int{c[2]} << ' ' << int{c[1]} << ' '
          << int{c[0]} << '\n';
    }
  }
  return out.good();
}

bool readPly(const std::string& path, PointCloud& cloud) {
  cloud.clear();
  std::ifstream in(path, std::ios::binary);
  std::string line;
  if (!std::getline(in, line) || line != "ply") return false;
  bool binary = false;
  std::size_t count = 0;
  while (std::getline(in, line) && line != "end_header") {
    std::istringstream words(line);
    std::string word;
    words >> word;
    if (word == "format") {
      words >> word;
      binary = word == "binary_little_endian";
      if (!binary && word != "ascii") return false;
    } else if (word == "element") {
      words >> word >> count;
    }
  }
  if (!in || count > (std::size_t{1} << 31)) return false;
  for (std::size_t i = 0; i < count; ++i) {
    float xyz[3];
    int rgb[3];
    if (binary) {
      unsigned char bytes[3];
      in.read(reinterpret_cast<char*>(xyz), sizeof(xyz));
      in.read(reinterpret_cast<char*>(bytes), sizeof(bytes));
      for (int k = 0; k < 3; ++k) rgb[k] = bytes[k];
    } else {
      in >> xyz[0] >> xyz[1] >> xyz[2] >> rgb[0] >> rgb[1] >> rgb[2];
    }
    if (!in) return false;
    cloud.points.emplace_back(xyz[0], xyz[1], xyz[2]);
    cloud.colors_bgr.push_back({static_cast<std::uint8_t>(rgb[2]),
                                static_cast<std::uint8_t>(rgb[1]),
                                static_cast<std::uint8_t>(rgb[0])});
  }
  return true;
}

bool saveOccupancyGrid(const OccupancyGrid2D& grid, const std::string& path, std::string* error) {
  if (grid.cells.empty() || grid.cells.type() != CV_8UC1) {
    return fail(error, "cannot save an empty occupancy grid to " + path);
  }
  cv::Mat image(grid.cells.size(), CV_8UC1);
  for (int row = 0; row < grid.cells.rows; ++row) {
    // Image row 0 is the top, i.e. the highest v.
    const std::uint8_t* src = grid.cells.ptr<std::uint8_t>(grid.cells.rows - 1 - row);
    std::uint8_t* dst = image.ptr<std::uint8_t>(row);
    for (int col = 0; col < grid.cells.cols; ++col) {
      dst[col] = src[col] == OccupancyGrid2D::kOccupied ? 0
                 : src[col] == OccupancyGrid2D::kFree   ? 254
                                                        : 205;
    }
  }
  const std::filesystem::path file(path);
  const std::string extension = file.extension().string();
  std::vector<std::uint8_t> bytes;
  if (extension == ".png") {
    if (!cv::imencode(".png", image, bytes)) return fail(error, "PNG encoding failed");
  } else if (extension == ".pgm") {
    const std::string header =
        "P5\n" + std::to_string(image.cols) + " " + std::to_string(image.rows) + "\n255\n";
    bytes.assign(header.begin(), header.end());
    bytes.insert(bytes.end(), image.datastart, image.dataend);
  } else {
    return fail(error, path + ": the grid file must end in .pgm or .png");
  }
  const bool image_ok = writeFileAtomically(
      path,
      [&bytes](std::ostream& out) {
        out.write(reinterpret_cast<const char*>(bytes.data()),
                  static_cast<std::streamsize>(bytes.size()));
        return true;
      },
      error);
  if (!image_ok) return false;
  std::filesystem::path yaml = file;
  yaml.replace_extension(".yaml");
  return writeFileAtomically(
      yaml.string(),
      [&](std::ostream& out) {
        out << "image: " << file.filename().string() << "\nresolution: " << grid.resolution_m
            << "\norigin: [" << grid.origin_u_m << ", " << grid.origin_v_m << ", 0.0]"
            << "\nnegate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n"
            << "# slamd: up axis " << toString(grid.up_axis) << ", height band ["
            << grid.min_height_m << ", " << grid.max_height_m << "] m\n";
        return true;
      },
      error);
}

bool writeOcTreeFile(const octomap::OcTree& tree, const std::string& path, std::string* error) {
  auto endsWith = [&path](const char* suffix) {
    const std::string tail(suffix);
    return path.size() >= tail.size() &&
           path.compare(path.size() - tail.size(), tail.size(), tail) == 0;
  };
  const bool full = endsWith(".ot");
  if (!full && !endsWith(".bt")) {
    if (error) *error = "'" + path + "': the map file must end in .bt or .ot";
    return false;
  }
  return writeFileAtomically(
      path, [&](std::ostream& out) { return full ? tree.write(out) : tree.writeBinaryConst(out); },
      error);
}

PointCloud occupiedVoxelCentres(const octomap::OcTree& tree) {
  PointCloud cloud;
  for (auto it = tree.begin_leafs(); it != tree.end_leafs(); ++it) {
    if (!tree.isNodeOccupied(*it)) continue;
    const octomap::point3d c = it.getCoordinate();
    cloud.points.emplace_back(c.x(), c.y(), c.z());
  }
  return cloud;
}

}  // namespace slamd
