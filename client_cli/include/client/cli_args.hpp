// The command line of `facescan`: commands, options, help texts and exit codes (notes/protocol.md).
// Parsing is pure (no DDS, no files) so every usage error is tested without a network.
#pragma once

#include <chrono>
#include <string>
#include <vector>

#include "recon/finishing.hpp"
#include "recon/status.hpp"
#include "wire/dds.hpp"

namespace facescan::client {

// Exit codes of the client (notes/protocol.md), the same for every command.
enum ExitCode : int {
    kExitOk = 0,
    kExitServerError = 1,    // the server refused: unknown session, bad request
    kExitUsage = 2,          // wrong command line
    kExitNoServer = 3,       // no server answered in time, or the server went away
    kExitCannotWrite = 4,    // the output file cannot be written
    kExitCannotServe = 5,    // view: the port cannot be bound, or the viewer's web files are missing
    kExitNotAllowed = 6,     // DDS Security: a bad identity file, or the identity's role may not do this
    kExitInterrupted = 130,  // Ctrl-C (128 + SIGINT, the shell convention)
};

enum class Command {
    kSessions,
    kWatch,
    kStatus,
    kMesh,
    kPreview,
    kTrajectory,
    kFinish,
    kReset,
    kView,
    kServers,
    kAudit,
    kDelete
};

struct CliOptions {
    Command command = Command::kSessions;
    bool help = false;       // --help: print the (command's) usage and exit 0
    std::string help_topic;  // the command named with --help; empty = the overview
    bool version = false;    // --version
    std::string session;     // SESSION argument (optional for watch)
    std::string output;      // -o FILE (mesh, preview; trajectory: empty = stdout)
    bool finish = false;     // mesh --finish: end the scan first
    // mesh --max-triangles/--keep/--close/--crop: finish the fetched model here (recon/finishing.hpp). Without a
    // head region on this side, keep = head means the largest part without its floating fragments.
    recon::FinishParams finish_params;
    bool finish_here = false;                   // any of those options was given
    bool vertex_colours = false;                // mesh --vertex-colours: never the texture, the vertex colours
    bool force = false;                         // delete --force: finish a running scan, then delete it
    std::string save_dir;                       // watch --save DIR: write each snapshot there
    std::string save_format = "ply";            // watch --save-format: ply|obj|stl|off|drc|glb
    bool json = false;                          // sessions/status --json: one JSON object per line
    uint16_t view_port = 8080;                  // view --port (0: any free port)
    std::string view_bind = "127.0.0.1";        // view --bind ADDRESS: this machine only unless told otherwise
    bool view_open = false;                     // view --open: open the page in the desktop's browser
    bool view_insecure_http = false;            // view --insecure-http: plain HTTP beyond loopback (warned)
    std::string view_tls;                       // view --tls DIR/NAME: HTTPS + WSS with a login
    std::string view_audit;                     // view --audit FILE: its audit trail (default: defaultViewAudit)
    std::vector<std::string> audit_files;       // audit FILE|DATA_DIR...: the trails to read
    wire::DomainConfig domain{0, "lan"};        // --domain N, --profile P, --security DIR/NAME
    std::chrono::milliseconds timeout{10'000};  // --timeout SECONDS: how long to wait for a server

    Status validate() const;
};

// Parses argv[1..]. InvalidArgument with a one-line message for every usage error (the caller prints it with
// the usage and exits kExitUsage). `--help` anywhere wins over other errors of the same command.
StatusOr<CliOptions> parseArgs(const std::vector<std::string>& args);

// Usage text: the overview when `command` is empty/unknown, else that command's page.
std::string usageText(const std::string& command = "");
std::string commandName(Command command);

}  // namespace facescan::client
