// Where the real data of ../shared/data lives, for tests and benchmarks. Never copied into the repo.
// FACESCAN_DATA_DIR overrides; otherwise <source>/../shared/data. Tests that need it skip with a clear message.
#pragma once

#include <cstdlib>
#include <filesystem>
#include <optional>
#include <string>

namespace facescan::testing {

inline std::optional<std::filesystem::path> sharedDataDir() {
    if (const char* env = std::getenv("FACESCAN_DATA_DIR"); env && *env) {
        if (std::filesystem::is_directory(env)) return std::filesystem::path(env);
        return std::nullopt;
    }
#ifdef FACESCAN_SOURCE_DIR
    const std::filesystem::path p = std::filesystem::path(FACESCAN_SOURCE_DIR) / ".." / "shared" / "data";
    if (std::filesystem::is_directory(p)) return std::filesystem::weakly_canonical(p);
#endif
    return std::nullopt;
}

// The folder `name` of the shared data, or nullopt when absent (a user's fresh machine).
inline std::optional<std::filesystem::path> sharedData(const std::string& name) {
    auto root = sharedDataDir();
    if (!root || !std::filesystem::exists(*root / name)) return std::nullopt;
    return *root / name;
}

}  // namespace facescan::testing

// Inside a TEST: binds `var` to the data folder `name`, or skips the test saying what is missing.
#define FACESCAN_REQUIRE_DATA(var, name)                                                            \
    auto var##_opt = ::facescan::testing::sharedData(name);                                         \
    if (!var##_opt) {                                                                               \
        GTEST_SKIP() << "shared data '" << (name) << "' not found (looked in FACESCAN_DATA_DIR or " \
                     << "../shared/data beside the checkout); this test needs the real data";       \
    }                                                                                               \
    const std::filesystem::path var = *var##_opt
