#include "slamd/common/file_io.hpp"

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <streambuf>
#include <vector>

namespace slamd {

namespace {

/// An output stream buffer on a POSIX file descriptor, so the content can be fsynced.
class FdOutputBuffer : public std::streambuf {
 public:
  explicit FdOutputBuffer(int fd) : fd_(fd), buffer_(1 << 16) {
    setp(buffer_.data(), buffer_.data() + buffer_.size());
  }
  bool failed() const { return failed_; }
  int savedErrno() const { return errno_; }

 protected:
  int_type overflow(int_type ch) override {
    if (!flushBuffer()) return traits_type::eof();
    if (!traits_type::eq_int_type(ch, traits_type::eof())) {
      *pptr() = traits_type::to_char_type(ch);
      pbump(1);
    }
    return traits_type::not_eof(ch);
  }
  int sync() override { return flushBuffer() ? 0 : -1; }

 private:
  bool flushBuffer() {
    const char* data = pbase();
    std::size_t remaining = static_cast<std::size_t>(pptr() - pbase());
    while (remaining > 0 && !failed_) {
      const ssize_t written = ::write(fd_, data, remaining);
      if (written < 0) {
        if (errno == EINTR) continue;
        failed_ = true;
        errno_ = errno;
        break;
      }
      data += written;
      remaining -= static_cast<std::size_t>(written);
    }
    setp(buffer_.data(), buffer_.data() + buffer_.size());
    return !failed_;
  }

  int fd_;
  std::vector<char> buffer_;
  bool failed_ = false;
  int errno_ = 0;
};

bool fail(std::string* error, const std::string& text) {
  if (error) *error = text;
  return false;
}

std::string errnoText(int error_number) { return std::strerror(error_number); }

/// Streams the writer's content into `fd`; false with `why` when the writer refuses or throws, or
/// a write fails.
bool writeThrough(int fd, const std::function<bool(std::ostream&)>& writer, std::string& why) {
  FdOutputBuffer buffer(fd);
  std::ostream stream(&buffer);
  bool accepted = false;
  try {
    accepted = writer(stream);
  } catch (const std::exception& e) {
    why = std::string("writer threw: ") + e.what();
  }
  stream.flush();
  // A failed write comes first: a writer that checks its stream (OctoMap's) gives up because
  // of it, and the reason to report is the system's ("No space left on device").
  if (buffer.failed()) {
    why = "write failed: " + errnoText(buffer.savedErrno());
    return false;
  }
  if (!accepted) {
    if (why.empty()) why = "the writer abandoned the content";
    return false;
  }
  if (!stream.good()) {
    why = "write failed: " + errnoText(buffer.savedErrno());
    return false;
  }
  return true;
}

}  // namespace

std::string temporaryPathFor(const std::string& path) { return path + ".tmp"; }

bool writeFileAtomically(const std::string& path, const std::function<bool(std::ostream&)>& writer,
                         std::string* error) {
  const std::string tmp = temporaryPathFor(path);
  const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) return fail(error, "cannot create " + tmp + ": " + errnoText(errno));
  std::string why;
  bool ok = writeThrough(fd, writer, why);
  // Data must be on disk before the rename makes it visible under the final name.
  if (ok && ::fsync(fd) != 0) {
    ok = false;
    why = "fsync failed: " + errnoText(errno);
  }
  if (::close(fd) != 0 && ok) {
    ok = false;
    why = "close failed: " + errnoText(errno);
  }
  if (!ok) {
    ::unlink(tmp.c_str());
    return fail(error, "cannot write " + path + ": " + why);
  }
  if (::rename(tmp.c_str(), path.c_str()) != 0) {
    const int saved = errno;
    ::unlink(tmp.c_str());
    return fail(error, "cannot rename " + tmp + " to " + path + ": " + errnoText(saved));
  }
  // The rename is durable only once the directory entry is on disk.
  std::filesystem::path dir = std::filesystem::path(path).parent_path();
  if (dir.empty()) dir = ".";
  const int dir_fd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (dir_fd >= 0) {
    const bool synced = ::fsync(dir_fd) == 0;
    const int saved = errno;
    ::close(dir_fd);
    if (!synced) return fail(error, "fsync of " + dir.string() + " failed: " + errnoText(saved));
  }
  return true;
}

bool writeOutputFile(const std::string& path, const std::function<bool(std::ostream&)>& writer,
                     std::string* error) {
  std::error_code status_error;
  const auto status = std::filesystem::status(path, status_error);
  if (status_error || status.type() == std::filesystem::file_type::regular ||
      status.type() == std::filesystem::file_type::not_found) {
    return writeFileAtomically(path, writer, error);
  }
  if (status.type() == std::filesystem::file_type::directory) {
    return fail(error, "cannot write " + path + ": it is a directory");
  }
  // A device, FIFO or socket (/dev/stdout, a pipe): written in place, every write checked;
  // renaming a temporary file over it would replace the device node.
  const int fd = ::open(path.c_str(), O_WRONLY | O_CLOEXEC);
  if (fd < 0) return fail(error, "cannot open " + path + ": " + errnoText(errno));
  std::string why;
  bool ok = writeThrough(fd, writer, why);
  if (::close(fd) != 0 && ok) {
    ok = false;
    why = "close failed: " + errnoText(errno);
  }
  return ok || fail(error, "cannot write " + path + ": " + why);
}

std::vector<std::string> removeStaleTemporaryFiles(const std::vector<std::string>& output_paths,
                                                   const std::string& folder,
                                                   const std::vector<std::string>& suffixes) {
  namespace fs = std::filesystem;
  std::vector<std::string> candidates;
  for (const std::string& path : output_paths) {
    if (!path.empty()) candidates.push_back(temporaryPathFor(path));
  }
  std::error_code error;
  if (!folder.empty() && fs::is_directory(folder, error)) {
    const std::string tmp_suffix = temporaryPathFor("");
    for (const auto& entry : fs::directory_iterator(folder, error)) {
      const std::string name = entry.path().filename().string();
      for (const std::string& suffix : suffixes) {
        const std::string ending = suffix + tmp_suffix;
        if (name.size() > ending.size() &&
            name.compare(name.size() - ending.size(), ending.size(), ending) == 0) {
          candidates.push_back(entry.path().string());
        }
      }
    }
  }
  std::vector<std::string> removed;
  for (const std::string& candidate : candidates) {
    if (fs::is_regular_file(fs::symlink_status(candidate, error)) && fs::remove(candidate, error)) {
      removed.push_back(candidate);
    }
  }
  return removed;
}

std::uint64_t fnv1a64(const void* data, std::size_t size, std::uint64_t hash) {
  const auto* bytes = static_cast<const std::uint8_t*>(data);
  for (std::size_t i = 0; i < size; ++i) {
    hash ^= bytes[i];
    hash *= 1099511628211ull;  // the 64-bit FNV prime
  }
  return hash;
}

bool readFileBytes(const std::string& path, std::vector<std::uint8_t>& bytes, std::string& error) {
  // Only regular files: a FIFO would block the reader forever and a directory "opens" with an
  // absurd size. The check follows symbolic links, as opening does.
  std::error_code status_error;
  const auto status = std::filesystem::status(path, status_error);
  if (status_error) {
    error = "cannot open " + path + ": " + status_error.message();
    return false;
  }
  if (status.type() != std::filesystem::file_type::regular) {
    error = path + " is not a regular file (" +
            (status.type() == std::filesystem::file_type::directory ? std::string("a directory")
             : status.type() == std::filesystem::file_type::fifo    ? std::string("a FIFO")
                                                                 : std::string("a special file")) +
            ")";
    return false;
  }
  std::ifstream in(path, std::ios::binary | std::ios::ate);
  if (!in) {
    error = "cannot open " + path;
    return false;
  }
  const std::streamoff size = in.tellg();
  if (size <= 0) {
    error = path + " is empty";
    return false;
  }
  bytes.resize(static_cast<std::size_t>(size));
  in.seekg(0);
  if (!in.read(reinterpret_cast<char*>(bytes.data()), size)) {
    error = "cannot read " + path;
    return false;
  }
  return true;
}

}  // namespace slamd
