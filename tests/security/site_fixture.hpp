// A fresh DDS Security site made by the real deploy/security/site.sh in a temporary folder of the test (removed
// at the end), and the in-process checks of its identities.
#pragma once

#include <unistd.h>

#include <filesystem>
#include <string>

#include "run_command.hpp"

namespace facescan::testing {

inline std::string siteScript() { return std::string(FACESCAN_SOURCE_DIR) + "/deploy/security/site.sh"; }

class TempSite {
 public:
    // Makes `tag`'s folder under the temporary directory and a site "SITE" in it (roles agent, server, client,
    // viewer); `ok()` says whether site.sh succeeded, `initOutput()` what it printed.
    explicit TempSite(const std::string& tag, const std::string& name = "lab")
        : root_(std::filesystem::temp_directory_path() / ("facescan_sec_" + tag + "_" + std::to_string(::getpid()))) {
        std::filesystem::remove_all(root_);
        std::filesystem::create_directories(root_);
        init_ = site("init " + dir().string() + " --name " + name);
    }
    ~TempSite() { std::filesystem::remove_all(root_); }
    TempSite(const TempSite&) = delete;
    TempSite& operator=(const TempSite&) = delete;

    bool ok() const { return init_.exit_code == 0; }
    const std::string& initOutput() const { return init_.out; }
    std::filesystem::path root() const { return root_; }  // the test's scratch folder (the site is root/site)
    std::filesystem::path dir() const { return root_ / "site"; }
    std::filesystem::path identity(const std::string& name) const { return dir() / name; }

    // site.sh with these arguments (output and exit code).
    static CommandRun site(const std::string& args) { return runCommand(siteScript() + " " + args); }
    CommandRun add(const std::string& role, const std::string& name, const std::string& extra = "") const {
        return site("add " + dir().string() + " " + role + " " + name + " " + extra);
    }
    CommandRun revoke(const std::string& name) const { return site("revoke " + dir().string() + " " + name); }

 private:
    std::filesystem::path root_;
    CommandRun init_;
};

}  // namespace facescan::testing
