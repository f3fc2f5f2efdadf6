// Internal helpers shared by the command implementations (not part of client_core's public API).
#pragma once

#include <atomic>
#include <memory>
#include <string>

#include "client/cli_args.hpp"
#include "client/scan_client.hpp"

namespace facescan::client::detail {

// Prints "facescan: error: <message>" on stderr and returns `code`.
int fail(int code, const std::string& message);

// The exit code of a failed network operation: no answer -> 3, refusal by a server -> 1.
int exitCodeForRequest(const Status& status);

// The client configuration of the options' domain, profile and timeout.
ClientConfig clientConfig(const CliOptions& options);
// Connects with clientConfig(options) (`commands`: see ClientConfig); on failure prints why and sets `exit_code`.
std::unique_ptr<ScanClient> connectOrFail(const CliOptions& options, int& exit_code, bool commands = true);

// Set by SIGINT/SIGTERM once installInterruptHandler() ran; long-running commands poll it.
extern std::atomic<bool> g_interrupted;
void installInterruptHandler();

int runWatch(const CliOptions& options);
int runView(const CliOptions& options);
int runAudit(const CliOptions& options);
int runDelete(const CliOptions& options);

}  // namespace facescan::client::detail
