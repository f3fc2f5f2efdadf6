// The commands of `facescan`, each returning its exit code (client/cli_args.hpp) and printing results on stdout,
// errors on stderr as "facescan: error: ...".
#pragma once

#include "client/cli_args.hpp"

namespace facescan::client {

// Runs the parsed command line (help and version included).
int runCommand(const CliOptions& options);

// The whole program: parse, run, map every failure to its exit code.
int facescanMain(int argc, char** argv);

}  // namespace facescan::client
