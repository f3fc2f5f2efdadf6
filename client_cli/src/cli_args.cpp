// Command-line parsing of `facescan`: one table of commands, the options each accepts, and their help pages.
#include "client/cli_args.hpp"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <map>
#include <set>

#include "client/mesh_file.hpp"
#include "client/view_server.hpp"
#include "wire/dds_options.hpp"
#include "wire/messages.hpp"

namespace facescan::client {
namespace {

struct CommandSpec {
    Command command;
    const char* name;
    int min_args;  // positional arguments (the session)
    int max_args;
    std::set<std::string> options;  // accepted command options besides the global ones
    const char* usage;
};

std::string globalOptions() {
    return "Options shared by every command (the DDS ones also by facescan-agent and facescan-server):\n" +
           wire::ddsOptionsHelp(24) +
           "  --timeout S           seconds to wait for a server before giving up (default 10)\n"
           "  --version             the version and the git commit it was built from\n"
           "  -h, --help            this help\n";
}

constexpr const char* kExitCodes =
    "Exit codes: 0 ok, 1 the server refused (unknown session, bad request), 2 usage error,\n"
    "            3 no server answered in time, 4 the output file cannot be written,\n"
    "            5 view cannot serve (port taken, web files missing),\n"
    "            6 not allowed (DDS Security: a bad identity, or its role may not do this), 130 interrupted.\n";

const std::vector<CommandSpec>& commandSpecs() {
    static const std::vector<CommandSpec> specs = {
        {Command::kSessions,
         "sessions",
         0,
         0,
         {"--json"},
         "Usage: facescan sessions [--json]\n"
         "Lists the scan sessions live on the domain (found by discovery): state, frames, fps, the server that\n"
         "owns each one and its standby (the server that takes over when the owner dies).\n"
         "  --json          one JSON object per session instead of the table\n"},
        {Command::kServers,
         "servers",
         0,
         0,
         {"--json"},
         "Usage: facescan servers [--json]\n"
         "Lists the facescan servers alive on the domain: sessions owned (of their capacity), sessions they stand\n"
         "by for, CPU load (cores), uptime and version. A server still on the network that has stopped working\n"
         "(frozen intake, overloaded) is marked NOT RESPONDING.\n"
         "  --json          one JSON object per server instead of the table\n"},
        {Command::kWatch,
         "watch",
         0,
         1,
         {"--save", "--save-format"},
         "Usage: facescan watch [SESSION] [--save DIR [--save-format ply|obj|stl|off|drc|glb]]\n"
         "Follows one scan live until it is finished (Ctrl-C stops watching; the scan goes on).\n"
         "Without SESSION it follows the newest live scan, waiting for one to start.\n"
         "On a terminal it redraws a small panel; into a pipe or log it prints one line per second.\n"
         "  --save DIR      write every mesh snapshot as it arrives: DIR/SESSION-SEQ.ply\n"
         "  --save-format F format of the saved snapshots (default ply)\n"},
        {Command::kStatus,
         "status",
         1,
         1,
         {"--json"},
         "Usage: facescan status SESSION [--json]\n"
         "Asks the servers who owns SESSION and prints its state, frame counts, per-stage times, its standby and\n"
         "the failovers it went through (count, last takeover time).\n"
         "  --json          one JSON object\n"},
        {Command::kMesh,
         "mesh",
         1,
         1,
         {"-o", "--finish", "--max-triangles", "--keep", "--close", "--crop", "--vertex-colours"},
         "Usage: facescan mesh SESSION -o FILE [--finish] [--vertex-colours]\n"
         "                    [--max-triangles N|web|avatar|print|full] [--keep head|all]\n"
         "                    [--close none|holes|watertight] [--crop X0,Y0,Z0,X1,Y1,Z1]\n"
         "Fetches the full-resolution mesh (the final one, or the current model while scanning) and writes it\n"
         "atomically. The format follows the extension: .ply (binary, colours), .obj and .off (colours),\n"
         ".stl (no colours), .drc (Draco, colours), .glb (glTF 2.0 binary, vertex colours). Positions are in\n"
         "metres, in the first camera's frame (x right, y down, z away from the camera); .glb uses glTF's axes\n"
         "(y up, the face looking along +z), the same mesh turned 180 degrees about x.\n"
         "A finished scan with colour has a texture (the colour camera's resolution, sharper than vertex colours):\n"
         ".glb then holds it as its base colour texture, .obj comes with FILE.mtl and FILE.png beside it, and\n"
         ".ply has texture coordinates and FILE.png beside it; the vertex colours are kept in .obj and .ply.\n"
         "The output says which files were written.\n"
         "  -o FILE         output file (required)\n"
         "  --finish        end the scan first (the server writes it to its data folder)\n"
         "  --vertex-colours  the mesh with vertex colours only, no texture (one file, as while scanning)\n"
         "The server's model is the tracked head alone, at full resolution unless the server was given a budget.\n"
         "These options finish it further here, before writing (the report says what changed):\n"
         "  --max-triangles N|web|avatar|print|full\n"
         "                  at most N triangles (at least 500) by quadric decimation that keeps the colours and\n"
         "                  the scan's rim; web 20000, avatar 50000, print 200000, full no budget. Prints the\n"
         "                  distance from the result to the full mesh (mean, p99, max mm)\n"
         "  --keep head|all head (default): drop floating fragments (parts under 1% of the largest); all: keep them\n"
         "  --close none|holes|watertight\n"
         "                  holes: fill holes up to 20 mm across; the seen surface stays where it was.\n"
         "                  watertight: close the head into a solid cut flat below the chin, for a 3D printer\n"
         "                  (closed, manifold, one piece). Here it has the mesh alone, re-meshed on 1.5 mm voxels\n"
         "                  (the report says how far the seen surface moved, about 0.05 mm); the server's\n"
         "                  --close watertight keeps the seen surface exactly. Too little of a head stays open\n"
         "  --crop X0,Y0,Z0,X1,Y1,Z1  keep only what lies inside this box (metres, the mesh's frame)\n"
         "                  (these four work on the vertex-coloured mesh: the texture is not fetched with them)\n"},
        {Command::kPreview,
         "preview",
         1,
         1,
         {"-o"},
         "Usage: facescan preview SESSION -o FILE.png\n"
         "Fetches a shaded picture of the current model, seen from the last camera pose.\n"
         "  -o FILE.png     output file (required)\n"},
        {Command::kTrajectory,
         "trajectory",
         1,
         1,
         {"-o"},
         "Usage: facescan trajectory SESSION [-o FILE]\n"
         "Fetches the camera trajectory as TUM lines `timestamp tx ty tz qx qy qz qw` (camera to the first\n"
         "camera's frame).\n"
         "  -o FILE         output file (default: standard output)\n"},
        {Command::kFinish,
         "finish",
         1,
         1,
         {},
         "Usage: facescan finish SESSION\n"
         "Ends the scan now: the server makes the final mesh and writes the session to its data folder.\n"},
        {Command::kView,
         "view",
         0,
         0,
         {"--port", "--bind", "--open", "--insecure-http", "--tls", "--audit"},
         "Usage: facescan view [--port 8080] [--bind 127.0.0.1] [--open] [--tls DIR/NAME | --insecure-http]\n"
         "Serves a web page that shows every scan on the domain live: the sessions with state, frames, fps and\n"
         "server; a 3D view of a session's latest snapshot (drag to turn, wheel to zoom, right-drag to pan) that\n"
         "updates as the scan grows; progress and the server's messages; and downloads of the mesh as PLY, OBJ,\n"
         "STL and GLB. Browsers decode the snapshots themselves (three.js, served from this machine: no internet\n"
         "needed). Runs until Ctrl-C.\n"
         "  --port N        TCP port (default 8080; 0 picks a free one, printed at start)\n"
         "  --bind ADDRESS  IP address to listen on (default 127.0.0.1: this machine only; 0.0.0.0: the LAN)\n"
         "  --open          open the page in this desktop's browser\n"
         "  --tls DIR/NAME  HTTPS and WSS with a login: DIR/NAME/web.pem (facescan-site web SITE NAME --host\n"
         "                  THIS-HOST) and DIR/NAME/logins (facescan-site login SITE NAME USER). Browsers must trust\n"
         "                  the site's CA (SITE/identity_ca.pem); sessions end after 15 min unused (12 h at most);\n"
         "                  after 5 wrong passwords from an address or for a user, each try waits (30 s, doubling)\n"
         "  --audit FILE    the viewer's audit trail: every snapshot and mesh fetched, session followed and login,\n"
         "                  with the login (default $XDG_STATE_HOME/facescan/view-audit.log; facescan audit reads it)\n"
         "  --insecure-http allow a --bind other machines reach although the page is plain HTTP without a login:\n"
         "                  anyone on the network sees and downloads every scan. Refused without it; it warns at\n"
         "                  every start. From another machine, an SSH tunnel to 127.0.0.1 is the safe way:\n"
         "                  ssh -L 8080:127.0.0.1:8080 THIS-HOST, then open http://127.0.0.1:8080/ there\n"},
        {Command::kDelete,
         "delete",
         1,
         1,
         {"--force"},
         "Usage: facescan delete SESSION [--force]\n"
         "Erases a scan from every server on the domain (a person's right to erasure): its results, replicas and\n"
         "the files of every owner it had, in each server's data dir, and prints what each server removed. Each\n"
         "server keeps a tombstone, so nothing writes the scan again, and passes the request on: a server that is\n"
         "down now erases its copy when it comes back. A scan still being scanned is refused unless --force.\n"
         "  --force         finish the scan first if it is still running, then erase it\n"},
        {Command::kAudit,
         "audit",
         1,
         16,
         {"--session", "--json"},
         "Usage: facescan audit FILE|DATA_DIR... [--session SESSION] [--json]\n"
         "Prints audit trails: a server's (DATA_DIR/audit.log: every command it answered, with the client that\n"
         "sent it, its DDS Security identity's name first) and the viewer's (view --audit: every snapshot and mesh\n"
         "fetched, session followed and login, with the viewer login), oldest first. Nothing here changes them.\n"
         "  --session S     only the records of session S\n"
         "  --json          one JSON object per record\n"},
        {Command::kReset,
         "reset",
         1,
         1,
         {},
         "Usage: facescan reset SESSION\n"
         "Clears the model of a scan and starts again from the next frame (the session stays).\n"},
    };
    return specs;
}

const CommandSpec* findSpec(const std::string& name) {
    for (const CommandSpec& spec : commandSpecs()) {
        if (name == spec.name) return &spec;
    }
    return nullptr;
}

bool takesValue(const std::string& option) {
    static const std::set<std::string> kValued = {
        "--timeout", "-o",      "--save", "--save-format", "--port",  "--bind",   "--max-triangles",
        "--keep",    "--close", "--crop", "--tls",         "--audit", "--session"};
    return kValued.count(option) > 0 || wire::isDdsOption(option);
}

template <typename T>
bool parseNumber(const std::string& text, T& value) {
    const char* end = text.data() + text.size();
    auto [ptr, ec] = std::from_chars(text.data(), end, value);
    return ec == std::errc() && ptr == end;
}

}  // namespace

std::string commandName(Command command) {
    for (const CommandSpec& spec : commandSpecs()) {
        if (spec.command == command) return spec.name;
    }
    return "?";
}

std::string usageText(const std::string& command) {
    if (const CommandSpec* spec = findSpec(command)) {
        return std::string(spec->usage) + "\n" + globalOptions() + "\n" + kExitCodes;
    }
    return std::string(
               "Usage: facescan [OPTIONS] COMMAND [ARGS]\n"
               "The client of facescan: watch scans live and fetch their results over DDS.\n"
               "\n"
               "Commands:\n"
               "  sessions                       the live sessions on the domain, with state, frames and owner\n"
               "  servers                        the servers on the domain, with capacity, load and uptime\n"
               "  watch [SESSION]                follow a scan live (--save DIR keeps every snapshot)\n"
               "  status SESSION                 state, frame counts and timings of one session\n"
               "  mesh SESSION -o FILE           the mesh as .ply .obj .stl .off .drc or .glb (--finish ends the "
               "scan)\n"
               "  preview SESSION -o FILE.png    a shaded picture of the current model\n"
               "  trajectory SESSION [-o FILE]   the camera trajectory (TUM text)\n"
               "  finish SESSION                 end a scan now\n"
               "  reset SESSION                  clear a scan's model and start again\n"
               "  view [--port N] [--open]       watch every scan in a web browser (live 3D, downloads)\n"
               "  delete SESSION                 erase a scan from every server (--force: even a running one)\n"
               "  audit FILE|DATA_DIR...         who fetched, reset or finished which scan (--session S)\n"
               "\n") +
           globalOptions() + "\n" + kExitCodes + "\n'facescan COMMAND --help' describes one command.\n";
}

Status CliOptions::validate() const {
    RETURN_IF_ERROR(domain.validate());
    if (timeout.count() <= 0) return invalidArgument("--timeout must be positive");
    if (!session.empty()) {
        if (Status s = wire::validateSessionId(session); !s.isOk()) return invalidArgument(s.message());
    }
    return Status::ok();
}

StatusOr<CliOptions> parseArgs(const std::vector<std::string>& args) {
    CliOptions options;
    const CommandSpec* spec = nullptr;
    std::vector<std::string> positional;
    std::map<std::string, std::string> values;  // option -> value ("" for flags)
    bool help = false;

    for (size_t i = 0; i < args.size(); ++i) {
        std::string arg = args[i];
        if (arg == "-h" || arg == "--help") {
            help = true;
            continue;
        }
        if (arg == "--version") {
            options.version = true;
            continue;
        }
        if (arg.size() > 1 && arg[0] == '-') {
            std::string value;
            bool has_value = false;
            if (const size_t eq = arg.find('='); arg.starts_with("--") && eq != std::string::npos) {
                value = arg.substr(eq + 1);
                arg = arg.substr(0, eq);
                has_value = true;
            }
            if (arg == "--output") arg = "-o";
            if (takesValue(arg)) {
                if (!has_value) {
                    if (i + 1 >= args.size()) return invalidArgument(arg + " needs a value");
                    value = args[++i];
                }
            } else if (has_value) {
                return invalidArgument(arg + " takes no value");
            }
            if (values.count(arg)) return invalidArgument(arg + " given twice");
            values[arg] = value;
            continue;
        }
        if (!spec) {
            if (arg == "help") {  // `facescan help [COMMAND]`
                help = true;
                continue;
            }
            spec = findSpec(arg);
            if (!spec) {
                if (help) break;  // `facescan help nonsense`: the overview
                return invalidArgument("unknown command '" + arg + "'");
            }
            continue;
        }
        positional.push_back(arg);
    }

    if (help || options.version) {
        options.help = help;
        if (spec) {
            options.command = spec->command;
            options.help_topic = spec->name;
        }
        return options;
    }
    if (!spec) return invalidArgument("no command given");
    options.command = spec->command;

    for (const auto& [option, value] : values) {
        const bool global = wire::isDdsOption(option) || option == "--timeout";
        if (!global && !spec->options.count(option)) {
            return invalidArgument("unknown option " + option + " for '" + spec->name + "'");
        }
        if (wire::isDdsOption(option)) {
            RETURN_IF_ERROR(wire::applyDdsOption(options.domain, option, value));
        } else if (option == "--timeout") {
            double seconds = 0;
            if (!parseNumber(value, seconds) || !std::isfinite(seconds) || seconds <= 0 || seconds > 86400) {
                return invalidArgument("--timeout must be seconds > 0, got '" + value + "'");
            }
            options.timeout = std::chrono::milliseconds(static_cast<int64_t>(std::ceil(seconds * 1000)));
        } else if (option == "-o") {
            if (value.empty()) return invalidArgument("-o needs a file name");
            options.output = value;
        } else if (option == "--finish") {
            options.finish = true;
        } else if (option == "--max-triangles") {
            ASSIGN_OR_RETURN(options.finish_params.max_triangles, recon::parseTriangleBudget(value));
            options.finish_here = true;
        } else if (option == "--keep") {
            ASSIGN_OR_RETURN(options.finish_params.keep, recon::parseKeepParts(value));
            options.finish_here = true;
        } else if (option == "--close") {
            ASSIGN_OR_RETURN(options.finish_params.close, recon::parseClosingMode(value));
            options.finish_here = true;
        } else if (option == "--crop") {
            ASSIGN_OR_RETURN(options.finish_params.crop_m, recon::parseCropBox(value));
            options.finish_here = true;
        } else if (option == "--vertex-colours") {
            options.vertex_colours = true;
        } else if (option == "--force") {
            options.force = true;
        } else if (option == "--save") {
            if (value.empty()) return invalidArgument("--save needs a folder");
            options.save_dir = value;
        } else if (option == "--save-format") {
            options.save_format = value;
            if (!meshFormatFor("x." + value).isOk()) {
                return invalidArgument("--save-format must be ply, obj, stl, off, drc or glb, got '" + value + "'");
            }
        } else if (option == "--json") {
            options.json = true;
        } else if (option == "--port") {
            if (!parseNumber(value, options.view_port)) {
                return invalidArgument("--port must be a TCP port 0..65535, got '" + value + "'");
            }
        } else if (option == "--bind") {
            options.view_bind = value;
        } else if (option == "--open") {
            options.view_open = true;
        } else if (option == "--insecure-http") {
            options.view_insecure_http = true;
        } else if (option == "--audit") {
            if (value.empty()) return invalidArgument("--audit needs a file name");
            options.view_audit = value;
        } else if (option == "--session") {
            if (Status s = wire::validateSessionId(value); !s.isOk())
                return invalidArgument("--session: " + s.message());
            options.session = value;
        } else if (option == "--tls") {
            if (value.empty()) return invalidArgument("--tls needs the viewer's identity folder DIR/NAME");
            options.view_tls = value;
        }
    }

    const int n = static_cast<int>(positional.size());
    if (n < spec->min_args) return invalidArgument(std::string("'") + spec->name + "' needs a SESSION");
    if (n > spec->max_args) return invalidArgument("unexpected argument '" + positional[spec->max_args] + "'");
    if (options.command == Command::kAudit) {
        options.audit_files = positional;
    } else if (n > 0) {
        options.session = positional[0];
    }

    if (options.command == Command::kMesh) {
        if (options.output.empty()) return invalidArgument("'mesh' needs -o FILE (.ply .obj .stl .off .drc .glb)");
        if (Status s = meshFormatFor(options.output).status(); !s.isOk()) return s;
    }
    if (options.command == Command::kPreview) {
        if (options.output.empty()) return invalidArgument("'preview' needs -o FILE.png");
        std::string ext = std::filesystem::path(options.output).extension().string();
        std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return std::tolower(c); });
        if (ext != ".png") return invalidArgument("the preview is a PNG picture: -o must end in .png");
    }
    if (options.command == Command::kView) {
        ViewServerConfig server;
        server.bind = options.view_bind;
        server.insecure_http = options.view_insecure_http;
        server.tls_dir = options.view_tls;
        if (!options.view_tls.empty() && options.view_insecure_http) {
            return invalidArgument("--tls and --insecure-http contradict each other: choose one");
        }
        if (Status s = server.validate(); !s.isOk()) return s;
    }
    if (!values.count("--save") && values.count("--save-format")) {
        return invalidArgument("--save-format needs --save DIR");
    }
    RETURN_IF_ERROR(options.validate());
    return options;
}

}  // namespace facescan::client
