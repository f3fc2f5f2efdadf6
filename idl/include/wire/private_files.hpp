// Files that hold a person's face (scans, replicas, recordings) are readable by their owner only, whoever runs the
// program and whatever its umask: folders 0700, files 0600. Face geometry used to identify someone is special-
// category personal data (GDPR Art. 9), and a server run by hand must protect it as well as the packaged service.
// One set of helpers for the server's data dir and the agent's recordings.
#pragma once

#include <filesystem>

#include "recon/status.hpp"

namespace facescan::wire {

// What protects these files today, for help texts and start-up logs: owner-only modes, no encryption at rest.
extern const char* const kFileProtectionSummary;

// Creates `dir` and each missing parent as 0700 (parents that exist are left as they are) and makes an existing
// `dir` 0700. Refused with the reason: a shared folder such as /tmp (sticky bit: its other users' files would go
// private too), a folder this user may not chmod, or a path that is not a folder.
Status createPrivateDir(const std::filesystem::path& dir);

// Makes a file that a library wrote with its own mode (OpenCV, iostreams) 0600. Call it before anything else can
// reach the file: in a folder made by createPrivateDir, nobody else can reach it in between.
Status makeFilePrivate(const std::filesystem::path& file);

// Walks `dir` without following links: folders become 0700, regular files 0600 (what an older version, or a copy,
// left readable). Returns how many entries it changed.
StatusOr<int> makeTreePrivate(const std::filesystem::path& dir);

}  // namespace facescan::wire
