// A folder under the system's temp dir for the current test's files (a server's data dir, a log): emptied when it
// is made, removed once the test has passed, kept when it failed (its messages name what it holds). Test programs
// that left their data dirs behind filled CI's shared /tmp with a few hundred MB of scans a run.
#pragma once

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <mutex>
#include <string>
#include <vector>

namespace facescan::testing {

class ScratchDirs : public ::testing::EmptyTestEventListener {
 public:
    // TEMP/NAME-PID, empty (created when `create`).
    static std::filesystem::path make(const std::string& name, bool create = false) {
        const auto dir = std::filesystem::temp_directory_path() / (name + "-" + std::to_string(::getpid()));
        std::filesystem::remove_all(dir);
        if (create) std::filesystem::create_directories(dir);
        instance().add(dir);
        return dir;
    }

 private:
    static ScratchDirs& instance() {
        // Appended on first use; gtest owns its listeners and tells them of the end of the test under way too.
        static ScratchDirs* const listener = [] {
            auto* made = new ScratchDirs;
            ::testing::UnitTest::GetInstance()->listeners().Append(made);
            return made;
        }();
        return *listener;
    }
    void add(const std::filesystem::path& dir) {
        std::lock_guard lk(mutex_);
        dirs_.push_back(dir);
    }
    void OnTestEnd(const ::testing::TestInfo& info) override {
        std::lock_guard lk(mutex_);
        if (!info.result()->Failed()) {
            for (const auto& dir : dirs_) {
                std::error_code ec;
                std::filesystem::remove_all(dir, ec);
            }
        }
        dirs_.clear();
    }

    std::mutex mutex_;
    std::vector<std::filesystem::path> dirs_;
};

// The current test's scratch folder TEMP/NAME-PID (ScratchDirs).
inline std::filesystem::path scratchDir(const std::string& name, bool create = false) {
    return ScratchDirs::make(name, create);
}

}  // namespace facescan::testing
