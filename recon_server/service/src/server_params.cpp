#include "service/server_params.hpp"

#include <unistd.h>

#include <charconv>
#include <cmath>
#include <fstream>
#include <functional>
#include <map>

#include "wire/cluster_codec.hpp"
#include "wire/dds_options.hpp"

namespace facescan::service {
namespace {

StatusOr<double> parseNumber(const std::string& key, const std::string& value) {
    try {
        size_t used = 0;
        const double v = std::stod(value, &used);
        if (used != value.size() || !std::isfinite(v)) throw std::invalid_argument(value);
        return v;
    } catch (const std::exception&) {
        return invalidArgument(key + ": '" + value + "' is not a number");
    }
}

StatusOr<int> parseInt(const std::string& key, const std::string& value) {
    int v = 0;
    const auto [end, ec] = std::from_chars(value.data(), value.data() + value.size(), v);
    if (ec != std::errc() || end != value.data() + value.size()) {
        return invalidArgument(key + ": '" + value + "' is not an integer");
    }
    return v;
}

StatusOr<bool> parseBool(const std::string& key, const std::string& value) {
    if (value == "true" || value == "1" || value == "yes" || value == "on") return true;
    if (value == "false" || value == "0" || value == "no" || value == "off") return false;
    return invalidArgument(key + ": '" + value + "' is not a boolean (true/false)");
}

using Setter = std::function<Status(ServerParams&, const std::string& key, const std::string& value)>;

Setter floatField(float* (*field)(ServerParams&)) {
    return [field](ServerParams& p, const std::string& key, const std::string& value) -> Status {
        ASSIGN_OR_RETURN(const double v, parseNumber(key, value));
        *field(p) = static_cast<float>(v);
        return Status::ok();
    };
}
Setter intField(int* (*field)(ServerParams&)) {
    return [field](ServerParams& p, const std::string& key, const std::string& value) -> Status {
        ASSIGN_OR_RETURN(const int v, parseInt(key, value));
        *field(p) = v;
        return Status::ok();
    };
}
Setter boolField(bool* (*field)(ServerParams&)) {
    return [field](ServerParams& p, const std::string& key, const std::string& value) -> Status {
        ASSIGN_OR_RETURN(const bool v, parseBool(key, value));
        *field(p) = v;
        return Status::ok();
    };
}

#define FLOAT(name, expr)                                         \
    {                                                             \
        name, floatField([](ServerParams& p) { return &(expr); }) \
    }
#define INT(name, expr)                                         \
    {                                                           \
        name, intField([](ServerParams& p) { return &(expr); }) \
    }
#define BOOL(name, expr)                                         \
    {                                                            \
        name, boolField([](ServerParams& p) { return &(expr); }) \
    }

const std::map<std::string, Setter>& setters() {
    static const std::map<std::string, Setter> table = {
        // Recon core (recon::ReconParams and its per-stage structs).
        FLOAT("filter.sigma_space_px", p.recon.filter.sigma_space_px),
        FLOAT("filter.sigma_depth_m", p.recon.filter.sigma_depth_m),
        INT("filter.radius_px", p.recon.filter.radius_px),
        INT("filter.levels", p.recon.filter.levels),
        FLOAT("filter.min_depth_m", p.recon.filter.min_depth_m),
        FLOAT("filter.max_depth_m", p.recon.filter.max_depth_m),
        INT("icp.levels", p.recon.icp.levels),
        INT("icp.iterations0", p.recon.icp.iterations[0]),
        INT("icp.iterations1", p.recon.icp.iterations[1]),
        INT("icp.iterations2", p.recon.icp.iterations[2]),
        FLOAT("icp.max_rmse_m", p.recon.icp.max_rmse_m),
        FLOAT("icp.max_translation_m", p.recon.icp.max_translation_m),
        FLOAT("icp.max_rotation_deg", p.recon.icp.max_rotation_deg),
        INT("icp.min_inliers", p.recon.icp.min_inliers),
        INT("icp.max_failures_before_reacquire", p.recon.icp.max_failures_before_reacquire),
        INT("tsdf.resolution_vox", p.recon.tsdf.resolution_vox),
        FLOAT("tsdf.volume_size_m", p.recon.tsdf.volume_size_m),
        {"tsdf.voxel_size_m",  // sets the cube edge for the current resolution
         [](ServerParams& p, const std::string& key, const std::string& value) -> Status {
             ASSIGN_OR_RETURN(const double v, parseNumber(key, value));
             p.recon.tsdf.volume_size_m = static_cast<float>(v * p.recon.tsdf.resolution_vox);
             return Status::ok();
         }},
        FLOAT("tsdf.trunc_dist_m", p.recon.tsdf.trunc_dist_m),
        FLOAT("tsdf.max_weight", p.recon.tsdf.max_weight),
        INT("tsdf.max_blocks", p.recon.tsdf.max_blocks),
        FLOAT("raycast.step_trunc_fraction", p.recon.raycast.step_trunc_fraction),
        INT("mesh.stride_vox", p.recon.mesh.stride_vox),
        FLOAT("mesh.min_fragment_share", p.recon.mesh.min_fragment_share),
        INT("min_head_pixels", p.recon.min_head_pixels),
        INT("roi_margin_px", p.recon.roi_margin_px),
        INT("model_level", p.recon.model_level),
        INT("model_cast_every", p.recon.model_cast_every),
        INT("fuse_every", p.recon.fuse_every),
        INT("unfused_finest_level", p.recon.unfused_finest_level),
        // Detection and segmentation (recon::FacePipelineParams).
        BOOL("face.depth_only_fallback", p.face.depth_only_fallback),
        INT("face.redetect_every_frames", p.face.redetect_every_frames),
        {"face.roll",
         [](ServerParams& p, const std::string&, const std::string& value) -> Status {
             ASSIGN_OR_RETURN(p.face.roll_deg, recon::parseRoll(value));
             return Status::ok();
         }},
        FLOAT("face.detector.face_width_min_m", p.face.detector.face_width_min_m),
        FLOAT("face.detector.face_width_max_m", p.face.detector.face_width_max_m),
        FLOAT("face.segmenter.grow_jump_m", p.face.segmenter.grow_jump_m),
        // Finishing the final model (recon::FinishParams): the head alone, holes, a triangle budget.
        {"finish.max_triangles",
         [](ServerParams& p, const std::string&, const std::string& value) -> Status {
             ASSIGN_OR_RETURN(p.finish.max_triangles, recon::parseTriangleBudget(value));
             return Status::ok();
         }},
        {"finish.keep",
         [](ServerParams& p, const std::string&, const std::string& value) -> Status {
             ASSIGN_OR_RETURN(p.finish.keep, recon::parseKeepParts(value));
             return Status::ok();
         }},
        {"finish.close",
         [](ServerParams& p, const std::string&, const std::string& value) -> Status {
             ASSIGN_OR_RETURN(p.finish.close, recon::parseClosingMode(value));
             return Status::ok();
         }},
        {"finish.crop",
         [](ServerParams& p, const std::string&, const std::string& value) -> Status {
             if (value == "none") {
                 p.finish.crop_m.reset();
                 return Status::ok();
             }
             ASSIGN_OR_RETURN(p.finish.crop_m, recon::parseCropBox(value));
             return Status::ok();
         }},
        FLOAT("finish.max_hole_m", p.finish.max_hole_m),
        FLOAT("finish.min_part_share", p.finish.min_part_share),
        // The texture atlas (recon::TextureParams) and the colour keyframes it is baked from.
        INT("texture.max_keyframes", p.texture_keyframes.max_keyframes),
        {"texture.max_mib",
         [](ServerParams& p, const std::string& key, const std::string& value) -> Status {
             ASSIGN_OR_RETURN(const double v, parseNumber(key, value));
             if (!(v >= 1 && v <= 1024)) return invalidArgument(key + " must be in [1, 1024] MiB, got " + value);
             p.texture_keyframes.max_bytes = static_cast<size_t>(v * (1 << 20));
             return Status::ok();
         }},
        FLOAT("texture.keyframe_deg", p.texture_keyframes.min_angle_deg),
        INT("texture.max_atlas_px", p.texture.max_atlas_px),
        FLOAT("texture.texels_per_pixel", p.texture.texels_per_pixel),
        // The service.
        INT("snapshot_stride_vox", p.snapshot_stride_vox),
        FLOAT("snapshot_hz", p.snapshot_hz),
        FLOAT("snapshot_max_error_m", p.snapshot_max_error_m),
        FLOAT("status_hz", p.status_hz),
        INT("max_sessions", p.max_sessions),
        FLOAT("idle_timeout_s", p.idle_timeout_s),
        INT("keep_finished", p.keep_finished),
        FLOAT("keep_finished_s", p.keep_finished_s),
        INT("retain_days", p.retain_days),
        FLOAT("replica_interval_s", p.replica_interval_s),
        INT("replica_full_every", p.replica_full_every),
        INT("replica_zstd_level", p.replica_zstd_level),
        FLOAT("join_settle_s", p.join_settle_s),
        FLOAT("claim_settle_s", p.claim_settle_s),
        FLOAT("first_frame_timeout_s", p.first_frame_timeout_s),
        FLOAT("stall_limit_s", p.stall_limit_s),
        INT("queue_frames", p.queue_frames),
        {"data_dir",
         [](ServerParams& p, const std::string&, const std::string& value) -> Status {
             p.data_dir = value;
             return Status::ok();
         }},
        // The DDS options every program shares (wire/dds_options.hpp), also as config keys.
        {"domain", [](ServerParams& p, const std::string&,
                      const std::string& value) { return wire::applyDdsOption(p.domain, "--domain", value); }},
        {"profile", [](ServerParams& p, const std::string&,
                       const std::string& value) { return wire::applyDdsOption(p.domain, "--profile", value); }},
        {"security", [](ServerParams& p, const std::string&,
                        const std::string& value) { return wire::applyDdsOption(p.domain, "--security", value); }},
        {"server_id",
         [](ServerParams& p, const std::string&, const std::string& value) -> Status {
             p.server_id = value;
             return Status::ok();
         }},
    };
    return table;
}
#undef FLOAT
#undef INT
#undef BOOL

std::string trim(const std::string& s) {
    const size_t b = s.find_first_not_of(" \t\r");
    if (b == std::string::npos) return {};
    const size_t e = s.find_last_not_of(" \t\r");
    return s.substr(b, e - b + 1);
}

Status applyPreset(ServerParams& p, const std::string& preset) {
    if (preset == "face") {
        p.recon = recon::ReconParams::faceDefaults();
    } else if (preset == "fast") {
        p.recon = recon::ReconParams::fast();
    } else {
        return invalidArgument("--preset: '" + preset + "' is not a preset (face, fast)");
    }
    p.preset = preset;
    return Status::ok();
}

std::string defaultServerId() {
    char host[256] = {};
    if (gethostname(host, sizeof(host) - 1) != 0) host[0] = '\0';
    std::string id = std::string(host[0] ? host : "server");
    for (char& c : id) {
        const bool ok = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '-' ||
                        c == '_' || c == '.';
        if (!ok) c = '-';
    }
    if (id.size() > 48) id.resize(48);
    return id + "-" + std::to_string(getpid());
}

}  // namespace

Status ServerParams::validate() const {
    if (preset != "face" && preset != "fast") return invalidArgument("preset must be face or fast");
    if (Status s = recon.validate(); !s.isOk()) return invalidArgument("recon parameters: " + s.message());
    if (Status s = face.validate(); !s.isOk()) return invalidArgument("face pipeline parameters: " + s.message());
    if (Status s = finish.validate(); !s.isOk()) return invalidArgument("finishing: " + s.message());
    if (Status s = texture_keyframes.validate(); !s.isOk()) return s;
    if (Status s = texture.validate(); !s.isOk()) return invalidArgument("texture: " + s.message());
    if (snapshot_stride_vox < 1 || snapshot_stride_vox > 8) return invalidArgument("snapshot_stride_vox: 1..8");
    if (!(snapshot_hz >= 0 && snapshot_hz <= 30)) return invalidArgument("--snapshot-hz must be in [0, 30]");
    if (!(snapshot_max_error_m > 0 && snapshot_max_error_m <= 0.005f)) {
        return invalidArgument("snapshot_max_error_m must be in (0, 0.005] metres");
    }
    if (!(status_hz > 0 && status_hz <= 50)) return invalidArgument("status_hz must be in (0, 50]");
    if (max_sessions < 1 || max_sessions > 64) return invalidArgument("--max-sessions must be in [1, 64]");
    if (!(idle_timeout_s >= 1 && idle_timeout_s <= 86400)) {
        return invalidArgument("--idle-timeout-s must be in [1, 86400] seconds");
    }
    if (keep_finished < 0 || keep_finished > 10000) return invalidArgument("--keep-finished must be in [0, 10000]");
    if (!(keep_finished_s >= 0 && keep_finished_s <= 30 * 86400)) {
        return invalidArgument("--keep-finished-s must be in [0, 2592000] seconds (30 days)");
    }
    if (retain_days < 0 || retain_days > 36500) return invalidArgument("--retain-days must be in [0, 36500] days");
    if (queue_frames < 1 || queue_frames > 64) return invalidArgument("queue_frames must be in [1, 64]");
    if (data_dir.empty()) return invalidArgument("--data-dir must not be empty");
    if (Status s = wire::validateServerId(server_id); !s.isOk()) return invalidArgument("--server-id: " + s.message());
    if (!(replica_interval_s >= 0.05f && replica_interval_s <= 2.0f)) {
        return invalidArgument(
            "--replica-interval-s must be in [0.05, 2] seconds (a standby must be at most 2 s behind)");
    }
    if (replica_full_every < 1 || replica_full_every > 10000) return invalidArgument("replica_full_every: 1..10000");
    if (replica_zstd_level < 1 || replica_zstd_level > 19) return invalidArgument("replica_zstd_level: 1..19");
    if (!(join_settle_s >= 0 && join_settle_s <= 60))
        return invalidArgument("join_settle_s must be in [0, 60] seconds");
    if (!(claim_settle_s >= 0 && claim_settle_s <= 10)) return invalidArgument("claim_settle_s must be in [0, 10] s");
    if (!(stall_limit_s >= 1 && stall_limit_s <= 3600)) return invalidArgument("stall_limit_s must be in [1, 3600] s");
    if (!(first_frame_timeout_s >= 1 && first_frame_timeout_s <= 3600)) {
        return invalidArgument("first_frame_timeout_s must be in [1, 3600] seconds");
    }
    return domain.validate();
}

Status applySetting(ServerParams& params, const std::string& key, const std::string& value) {
    if (key == "preset") return applyPreset(params, value);
    const auto it = setters().find(key);
    if (it == setters().end()) return invalidArgument("unknown setting '" + key + "' (see --help for the keys)");
    return it->second(params, key, value);
}

std::vector<std::string> settingKeys() {
    std::vector<std::string> keys{"preset"};
    for (const auto& [key, setter] : setters()) keys.push_back(key);
    return keys;
}

Status loadConfigFile(const std::filesystem::path& path, ServerParams& params) {
    std::ifstream in(path);
    if (!in) return notFound("--config: cannot read '" + path.string() + "'");
    std::string line;
    int line_no = 0;
    while (std::getline(in, line)) {
        ++line_no;
        if (const size_t hash = line.find('#'); hash != std::string::npos) line.resize(hash);
        line = trim(line);
        if (line.empty()) continue;
        const size_t eq = line.find('=');
        const std::string where = path.string() + ":" + std::to_string(line_no) + ": ";
        if (eq == std::string::npos) return invalidArgument(where + "expected 'key = value'");
        const Status s = applySetting(params, trim(line.substr(0, eq)), trim(line.substr(eq + 1)));
        if (!s.isOk()) return Status(s.code(), where + s.message());
    }
    return Status::ok();
}

StatusOr<ParsedArgs> parseServerArgs(const std::vector<std::string>& args) {
    ParsedArgs out;
    out.params.server_id = defaultServerId();
    // Flag -> setting key; every flag takes one value.
    static const std::map<std::string, std::string> kFlags = {{"--snapshot-hz", "snapshot_hz"},
                                                              {"--max-sessions", "max_sessions"},
                                                              {"--idle-timeout-s", "idle_timeout_s"},
                                                              {"--keep-finished", "keep_finished"},
                                                              {"--keep-finished-s", "keep_finished_s"},
                                                              {"--retain-days", "retain_days"},
                                                              {"--data-dir", "data_dir"},
                                                              {"--profile", "profile"},
                                                              {"--domain", "domain"},
                                                              {"--security", "security"},
                                                              {"--server-id", "server_id"},
                                                              {"--replica-interval-s", "replica_interval_s"},
                                                              {"--preset", "preset"},
                                                              {"--max-triangles", "finish.max_triangles"},
                                                              {"--keep", "finish.keep"},
                                                              {"--close", "finish.close"},
                                                              {"--crop", "finish.crop"},
                                                              {"--roll", "face.roll"},
                                                              {"--config", ""},
                                                              {"--set", ""}};
    std::vector<std::pair<std::string, std::string>> pairs;
    for (size_t i = 0; i < args.size(); ++i) {
        const std::string& a = args[i];
        if (a == "--help" || a == "-h") {
            out.help = true;
            return out;
        }
        if (a == "--check") {
            out.check = true;
            continue;
        }
        std::string flag = a, value;
        bool has_value = false;
        if (const size_t eq = a.find('='); a.rfind("--", 0) == 0 && eq != std::string::npos) {
            flag = a.substr(0, eq);
            value = a.substr(eq + 1);
            has_value = true;
        }
        if (kFlags.find(flag) == kFlags.end()) return invalidArgument("unknown argument '" + a + "' (see --help)");
        if (!has_value) {
            if (i + 1 >= args.size()) return invalidArgument(flag + " needs a value");
            value = args[++i];
        }
        pairs.emplace_back(flag, value);
    }
    // Precedence: preset, then the config file, then flags.
    for (const auto& [flag, value] : pairs) {
        if (flag == "--preset") RETURN_IF_ERROR(applyPreset(out.params, value));
    }
    for (const auto& [flag, value] : pairs) {
        if (flag == "--config") RETURN_IF_ERROR(loadConfigFile(value, out.params));
    }
    for (const auto& [flag, value] : pairs) {
        if (flag == "--preset" || flag == "--config") continue;
        if (flag == "--set") {  // --set key=value: any config key from the command line
            const size_t eq = value.find('=');
            if (eq == std::string::npos) return invalidArgument("--set expects key=value, got '" + value + "'");
            RETURN_IF_ERROR(applySetting(out.params, trim(value.substr(0, eq)), trim(value.substr(eq + 1))));
            continue;
        }
        const Status s = applySetting(out.params, kFlags.at(flag), value);
        if (!s.isOk()) return Status(s.code(), flag + ": " + s.message());
    }
    RETURN_IF_ERROR(out.params.validate());
    return out;
}

std::string serverUsage() {
    std::string keys;
    for (const std::string& k : settingKeys()) keys += "  " + k + "\n";
    return "usage: facescan-server [options]\n"
           "Runs the reconstruction service: every scan session seen on the DDS domain gets its own pipeline\n"
           "(detection, segmentation, recon core) and worker; finished sessions are written to --data-dir.\n"
           "Several servers on one domain share the work: each session is owned by exactly one of them (the least\n"
           "loaded), replicated to a standby server and to --data-dir every --replica-interval-s, and taken over by\n"
           "the standby (or resumed by this server restarted on the same --data-dir) when its owner dies.\n\n"
           "options:\n"
           "  --preset face|fast      recon parameters preset (default face: Meyer's values)\n"
           "  --config FILE           'key = value' lines (keys below); flags override the file\n"
           "  --set KEY=VALUE         one config key from the command line\n"
           "  --snapshot-hz HZ        MeshSnapshot rate per session (default 1; 0 = none while scanning)\n"
           "  --max-sessions N        open sessions at once (default 4); when every server is full, new ones are\n"
           "                          refused in their status until one frees up\n"
           "  --idle-timeout-s S      finish a session after S seconds without frames (default 60)\n"
           "  --keep-finished N       finished sessions listed at most (default 16): their status stays on the domain\n"
           "                          (facescan sessions) and the server keeps a small record of each\n"
           "  --keep-finished-s S     a finished session is listed at most S seconds (default 600); its memory goes\n"
           "                          as soon as its files are written, and its files answer its commands later\n"
           "  --data-dir DIR          sessions go to DIR/SESSION/ (default ./facescan-data): their replica while\n"
           "                          scanning, the results when finished; DIR/SESSION/owner.json names the owner\n"
           "                          DIR is made 0700 and every file in it 0600, whoever runs the server: faces are\n"
           "                          personal data. Nothing is encrypted at rest: use an encrypted file system\n"
           "                          (LUKS) for the data dir where that is needed\n"
           "  --retain-days N         erase the sessions whose newest file in DIR is older than N days (finished "
           "scans\n"
           "                          and replicas left behind), at start and every hour, and say so in the log and\n"
           "                          DIR/audit.log; an erased session is never written again (default 0: keep)\n"
           "  --server-id ID          this server's name on the domain, unique (default HOST-PID)\n"
           "  --replica-interval-s S  seconds between replicas of a scan to its standby and data dir (default 1)\n"
           "  --max-triangles N|web|avatar|print|full\n"
           "                          the final model's triangle budget (quadric decimation keeping colours and the\n"
           "                          scan's rim; web 20000, avatar 50000, print 200000, full = no budget, the\n"
           "                          default); at least 500. summary.json's \"finish\" says how far it lies from\n"
           "                          the full mesh\n"
           "  --keep head|all         the final model holds the tracked head alone (default: no torso, background\n"
           "                          or floating fragments) or all the volume holds\n"
           "  --close none|holes|watertight\n"
           "                          holes: fill holes up to finish.max_hole_m (default 0.02 m) in the final model;\n"
           "                          watertight: close the head into a solid cut flat below the chin (closed,\n"
           "                          manifold, one piece: for a 3D printer); the seen surface stays where it was.\n"
           "                          A scan that saw too little of the head stays open (the log says why)\n"
           "  --crop X0,Y0,Z0,X1,Y1,Z1  keep only the final model inside this box (metres, the first camera's frame)\n"
           "  --roll auto|DEG         how the cameras are held: how far the person appears turned clockwise in the\n"
           "                          image, 0 to 345 degrees in steps of 15 (a phone in portrait: 90 or 270,\n"
           "                          upside down: 180, at a slant: the nearest step, e.g. 30); auto (the default)\n"
           "                          takes each agent's --roll, and where the agent gave none finds it from the\n"
           "                          frames and follows a camera that turns during the scan; a value here wins\n"
           "                          over the agents'\n"
           "  --check                 check the configuration (file, flags, DDS profile, data dir) and exit\n" +
           wire::ddsOptionsHelp(26) +
           "  --version               print the version and the git commit it was built from\n"
           "  --help                  this text\n\n"
           "config keys:\n" +
           keys;
}

}  // namespace facescan::service
