// One server per data dir (data_dir_lock.hpp): a second holder is refused with the first one's name and what to do,
// and the lock is free again once its holder is gone.
#include "service/data_dir_lock.hpp"

#include <gtest/gtest.h>

#include <filesystem>

namespace facescan::service {
namespace {

TEST(DataDirLock, ASecondServerOnTheSameDataDirIsRefusedWithTheHoldersName) {
    const auto dir = std::filesystem::temp_directory_path() / ("facescan-lock-" + std::to_string(::getpid()));
    std::filesystem::create_directories(dir);
    {
        auto first = DataDirLock::acquire(dir, "srv-first");
        ASSERT_TRUE(first.isOk()) << first.status().toString();
        auto second = DataDirLock::acquire(dir, "srv-second");
        ASSERT_FALSE(second.isOk());
        const std::string& why = second.status().message();
        EXPECT_NE(why.find("is in use by facescan-server 'srv-first' (pid " + std::to_string(::getpid())),
                  std::string::npos)
            << why;
        EXPECT_NE(why.find("each server needs a --data-dir of its own"), std::string::npos) << why;
    }
    // The first holder is gone (as a killed server's lock goes with its process): the next one gets it.
    EXPECT_TRUE(DataDirLock::acquire(dir, "srv-second").isOk());
    std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace facescan::service
