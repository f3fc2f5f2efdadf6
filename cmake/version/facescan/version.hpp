// The version a program prints with --version: "PROGRAM VERSION (commit HASH)", the commit that was built (or
// "unknown" outside a git checkout). Written by CMake (cmake/FacescanVersion.cmake); the man pages made with
// help2man read the same line.
#pragma once

#include <string>

namespace facescan {

// The project's version, e.g. "0.1.0".
const char* version();
// The git commit the build was configured from (12 hex digits), or "unknown".
const char* gitCommit();
// "PROGRAM VERSION (commit HASH)".
std::string versionLine(const std::string& program);
// Prints versionLine(program) and a newline on stdout.
void printVersion(const std::string& program);

}  // namespace facescan
