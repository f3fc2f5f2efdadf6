#include "wire/private_files.hpp"

#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <vector>

namespace facescan::wire {
namespace {
namespace fs = std::filesystem;

constexpr mode_t kPrivateDir = 0700;
constexpr mode_t kPrivateFile = 0600;

Status errnoStatus(const std::string& what, int err) {
    return Status(err == EPERM || err == EACCES ? StatusCode::kPermissionDenied : StatusCode::kUnavailable,
                  what + ": " + std::strerror(err));
}

// chmod when the mode differs; `changed` counts it.
Status narrow(const fs::path& path, const struct stat& st, mode_t mode, int* changed) {
    if ((st.st_mode & 07777) == mode) return Status::ok();
    if (::chmod(path.c_str(), mode) != 0) {
        return errnoStatus("cannot make " + path.string() + " private (mode " +
                               (mode == kPrivateDir ? "0700" : "0600") +
                               "); give it to the user that runs facescan (chown)",
                           errno);
    }
    if (changed) ++*changed;
    return Status::ok();
}

}  // namespace

const char* const kFileProtectionSummary =
    "scans and replicas are readable by this user only (folders 0700, files 0600); they are not encrypted at rest: "
    "put the data dir on an encrypted file system (LUKS) where that is needed";

Status createPrivateDir(const fs::path& dir) {
    if (dir.empty()) return invalidArgument("an empty folder name");
    // Each missing component from the top down, made 0700 by mkdir itself (the umask can only narrow it).
    std::vector<fs::path> missing;
    for (fs::path p = dir; !p.empty(); p = p.parent_path()) {
        struct stat st {};
        if (::lstat(p.c_str(), &st) == 0) break;
        missing.push_back(p);
        if (p == p.parent_path()) break;
    }
    for (auto it = missing.rbegin(); it != missing.rend(); ++it) {
        if (::mkdir(it->c_str(), kPrivateDir) != 0 && errno != EEXIST) {
            return errnoStatus("cannot create " + it->string(), errno);
        }
    }
    struct stat st {};
    if (::stat(dir.c_str(), &st) != 0) return errnoStatus("cannot read " + dir.string(), errno);
    if (!S_ISDIR(st.st_mode)) return invalidArgument(dir.string() + " is not a folder");
    if (st.st_mode & S_ISVTX) {
        return invalidArgument(dir.string() +
                               " is a shared folder (sticky bit, like /tmp): give facescan a folder of its own "
                               "inside it, which it makes private");
    }
    return narrow(dir, st, kPrivateDir, nullptr);
}

Status makeFilePrivate(const fs::path& file) {
    struct stat st {};
    if (::lstat(file.c_str(), &st) != 0) return errnoStatus("cannot read " + file.string(), errno);
    if (!S_ISREG(st.st_mode)) return invalidArgument(file.string() + " is not a regular file");
    return narrow(file, st, kPrivateFile, nullptr);
}

StatusOr<int> makeTreePrivate(const fs::path& dir) {
    int changed = 0;
    struct stat st {};
    if (::lstat(dir.c_str(), &st) != 0) return errnoStatus("cannot read " + dir.string(), errno);
    if (!S_ISDIR(st.st_mode)) return invalidArgument(dir.string() + " is not a folder");
    RETURN_IF_ERROR(narrow(dir, st, kPrivateDir, &changed));
    std::error_code ec;
    // The iterator does not follow links into other folders; lstat below does not follow links to files.
    for (fs::recursive_directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
        if (::lstat(it->path().c_str(), &st) != 0) continue;  // gone meanwhile
        if (S_ISDIR(st.st_mode)) {
            RETURN_IF_ERROR(narrow(it->path(), st, kPrivateDir, &changed));
        } else if (S_ISREG(st.st_mode)) {
            RETURN_IF_ERROR(narrow(it->path(), st, kPrivateFile, &changed));
        }
    }
    if (ec) return errnoStatus("cannot list " + dir.string(), ec.value());
    return changed;
}

}  // namespace facescan::wire
