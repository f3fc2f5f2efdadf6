// Where the programs find the data files facescan installs under <prefix>/share/facescan (DDS profiles in
// profiles/, and whatever later features add: web assets, ...). One lookup for every program, so that the same
// binary works from the build tree, from an installed tree wherever it was unpacked (a .deb in a scratch root),
// and from its configured prefix. Install side: facescan_install_data() in cmake/FacescanInstall.cmake.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include "recon/status.hpp"

namespace facescan::wire {

// The share/facescan folders searched, first match wins:
//   1. $FACESCAN_SHARE_DIR, when set (a folder laid out like share/facescan);
//   2. <folder of the running program>/../share/facescan (an installed tree: /usr/bin -> /usr/share/facescan);
//   3. the build tree's mirror <build>/share/facescan (programs run from the build tree; links to the sources);
//   4. the configured install location (CMAKE_INSTALL_PREFIX/share/facescan).
// Folders that do not exist are left out.
std::vector<std::filesystem::path> shareDirs();

// The first <dir>/<relative> that exists (relative: "profiles/lan.xml", "web"). NotFound names every folder
// searched and how to point the programs at another one.
StatusOr<std::filesystem::path> findShareFile(const std::string& relative);

}  // namespace facescan::wire
