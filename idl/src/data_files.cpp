#include "wire/data_files.hpp"

#include <cstdlib>
#include <system_error>

namespace facescan::wire {
namespace fs = std::filesystem;

std::vector<fs::path> shareDirs() {
    std::vector<fs::path> candidates;
    if (const char* env = std::getenv("FACESCAN_SHARE_DIR"); env && *env) candidates.emplace_back(env);
    std::error_code ec;
    const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
    if (!ec) candidates.push_back(exe.parent_path().parent_path() / "share" / "facescan");
#ifdef FACESCAN_BUILD_SHARE_DIR
    candidates.emplace_back(FACESCAN_BUILD_SHARE_DIR);
#endif
#ifdef FACESCAN_INSTALL_SHARE_DIR
    candidates.emplace_back(FACESCAN_INSTALL_SHARE_DIR);
#endif
    std::vector<fs::path> dirs;
    for (const fs::path& dir : candidates) {
        if (fs::is_directory(dir, ec)) dirs.push_back(dir.lexically_normal());
    }
    return dirs;
}

StatusOr<fs::path> findShareFile(const std::string& relative) {
    std::error_code ec;
    std::string searched;
    for (const fs::path& dir : shareDirs()) {
        const fs::path path = dir / relative;
        if (fs::exists(path, ec)) return path;
        searched += " " + dir.string();
    }
    if (searched.empty()) searched = " (no share/facescan folder found)";
    return notFound("facescan data file '" + relative + "' not found in:" + searched +
                    "; reinstall facescan, or set FACESCAN_SHARE_DIR to a folder holding " + relative);
}

}  // namespace facescan::wire
