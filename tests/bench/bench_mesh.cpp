// facescan-bench mesh: the meshes the service delivers, on the demo's scan (the synthetic Kinect
// filming the Lee Perry-Smith head at 0.7 m, seed 1, 150 frames, through the server's FacePipeline).
//  - Live snapshots at 1 Hz (every 30th frame of a 30 Hz stream): volume copy, marching cubes at the snapshot
//    stride (incremental: only blocks changed since the last snapshot, against a full re-mesh in the same run),
//    Draco encode at the snapshot error; the cost per session as a share of one core.
//  - The final mesh: Draco bytes, encode ms, decode ms (to arrays ready to write, normals recomputed), position
//    error, and the old wire (10-bit normals, decoded into OpenMesh's half-edge mesh) as the baseline.
//  - Defects (zero-area, duplicate triangles, unreferenced vertices, non-manifold edges and vertices) before
//    cleaning and in what a client decodes.
// Codec and mesh times are thread CPU ms (a busy shared machine does not inflate them); JSON keys:
// mesh{bytes,encode_ms,decode_ms,max_error_mm,triangles,defects{...}} snapshot{cpu_share,copy_ms,mesh_ms,...}.
#include <algorithm>
#include <cstdio>
#include <ctime>
#include <string>
#include <vector>

#include "bench_command.hpp"
#include "recon/indexed_mesh.hpp"
#include "recon/marching_cubes.hpp"
#include "recon/mesh_writer.hpp"
#include "recon/reconstructor.hpp"
#include "recon/scan_step.hpp"
#include "recon_input.hpp"
#include "wire/mesh_codec.hpp"

namespace facescan::bench {
namespace {

double threadMs() {
    timespec ts{};
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
    return double(ts.tv_sec) * 1e3 + double(ts.tv_nsec) * 1e-6;
}

struct SnapshotFigures {
    int count = 0;
    double copy_ms = 0, mesh_ms = 0, full_mesh_ms = 0, encode_ms = 0, max_total_ms = 0;
    double old_mesh_ms = 0, old_encode_ms = 0;  // the old wire: OpenMesh with gradient normals, normals sent
    double blocks = 0, changed = 0, remeshed = 0, triangles = 0, bytes = 0;
    bool equal_to_full = true;  // the incremental mesh had the full re-mesh's triangle and vertex counts
};

struct FinalFigures {
    size_t bytes = 0, triangles = 0, vertices = 0;
    double encode_ms = 0, decode_ms = 0, write_ply_ms = 0, max_error_mm = 0;
    size_t old_bytes = 0, unaligned_bytes = 0;
    double old_encode_ms = 0, old_decode_ms = 0;
    recon::MeshDefects raw, delivered;
};

void printDefects(const char* what, const recon::MeshDefects& d) {
    std::printf("  %-34s %10zu %10zu %12zu %10zu %10zu\n", what, d.zero_area_triangles, d.duplicate_triangles,
                d.unreferenced_vertices, d.non_manifold_edges, d.non_manifold_vertices);
}

std::string jsonDefects(const recon::MeshDefects& d) {
    char buf[200];
    std::snprintf(buf, sizeof buf,
                  "{\"zero_area\":%zu,\"duplicate_triangles\":%zu,\"unreferenced_vertices\":%zu,"
                  "\"non_manifold_edges\":%zu,\"non_manifold_vertices\":%zu}",
                  d.zero_area_triangles, d.duplicate_triangles, d.unreferenced_vertices, d.non_manifold_edges,
                  d.non_manifold_vertices);
    return buf;
}

// Final mesh figures; `repeat` passes of encode and decode after a warm-up.
bool measureFinal(const recon::IndexedMesh& mesh, const wire::MeshCodecParams& params, int repeat, FinalFigures& f) {
    std::vector<uint8_t> bytes;
    if (!wire::encodeMeshDraco(mesh, params, bytes).isOk()) return false;
    recon::IndexedMesh decoded;
    if (!wire::decodeMeshDraco(bytes.data(), bytes.size(), decoded).isOk()) return false;
    double t0 = threadMs();
    for (int r = 0; r < repeat; ++r) (void)wire::encodeMeshDraco(mesh, params, bytes);
    f.encode_ms = (threadMs() - t0) / repeat;
    t0 = threadMs();
    for (int r = 0; r < repeat; ++r) (void)wire::decodeMeshDraco(bytes.data(), bytes.size(), decoded);
    f.decode_ms = (threadMs() - t0) / repeat;
    t0 = threadMs();
    if (!recon::meshFileBytes(decoded, recon::MeshFileFormat::kPly).isOk()) return false;
    f.write_ply_ms = threadMs() - t0;
    f.bytes = bytes.size();
    f.triangles = decoded.triangleCount();
    f.vertices = decoded.vertexCount();
    f.raw = recon::countDefects(mesh);
    f.delivered = recon::countDefects(decoded);

    // Position error: a copy whose colours are vertex ids (colours are lossless) identifies each decoded vertex.
    recon::IndexedMesh ids = mesh;
    for (uint32_t i = 0; i < ids.vertexCount(); ++i) {
        ids.colours_rgb[i] = {uint8_t(i), uint8_t(i >> 8), uint8_t(i >> 16)};
    }
    if (!wire::encodeMeshDraco(ids, params, bytes).isOk()) return false;
    if (!wire::decodeMeshDraco(bytes.data(), bytes.size(), decoded).isOk()) return false;
    for (size_t v = 0; v < decoded.vertexCount(); ++v) {
        const recon::Rgb8& c = decoded.colours_rgb[v];
        const uint32_t i = c[0] | uint32_t(c[1]) << 8 | uint32_t(c[2]) << 16;
        if (i >= mesh.vertexCount()) return false;
        f.max_error_mm = std::max(f.max_error_mm, 1e3 * double((decoded.positions_m[v] - mesh.positions_m[i]).norm()));
    }

    // The same without aligning Draco's grid with the voxels.
    wire::MeshCodecParams unaligned = params;
    unaligned.lattice_step_m = 0.0f;
    if (!wire::encodeMeshDraco(mesh, unaligned, bytes).isOk()) return false;
    f.unaligned_bytes = bytes.size();

    // Baseline: the old wire, before normals were left to the receiver (10-bit normals; decoded into OpenMesh's
    // half-edge mesh).
    wire::MeshCodecParams old_params;
    old_params.normal_bits = 10;
    recon::IndexedMesh with_normals = mesh;
    recon::computeVertexNormals(with_normals);
    recon::Mesh old_decoded;
    t0 = threadMs();
    for (int r = 0; r < repeat; ++r) (void)wire::encodeMeshDraco(with_normals, old_params, bytes);
    f.old_encode_ms = (threadMs() - t0) / repeat;
    t0 = threadMs();
    for (int r = 0; r < repeat; ++r) (void)wire::decodeMeshDraco(bytes.data(), bytes.size(), old_decoded);
    f.old_decode_ms = (threadMs() - t0) / repeat;
    f.old_bytes = bytes.size();
    return true;
}

// Size and time of the final mesh per Draco speed, with and without colours: the evidence for the shipped speed.
void printSweep(const recon::IndexedMesh& mesh, const wire::MeshCodecParams& shipped) {
    std::printf("\n  %-18s %6s %10s %10s %10s\n", "attributes", "speed", "KB", "encode_ms", "decode_ms");
    for (const bool colours : {false, true}) {
        for (int speed = 0; speed <= 10; ++speed) {
            wire::MeshCodecParams p = shipped;
            p.speed = speed;
            p.colours = colours;
            std::vector<uint8_t> bytes;
            double t0 = threadMs();
            if (!wire::encodeMeshDraco(mesh, p, bytes).isOk()) continue;
            const double encode_ms = threadMs() - t0;
            recon::IndexedMesh decoded;
            t0 = threadMs();
            if (!wire::decodeMeshDraco(bytes.data(), bytes.size(), decoded).isOk()) continue;
            const double decode_ms = threadMs() - t0;
            std::printf("  %-18s %6d %10.1f %10.2f %10.2f\n", colours ? "positions+colours" : "positions", speed,
                        bytes.size() / 1024.0, encode_ms, decode_ms);
        }
    }
}

int runMesh(const std::vector<std::string>& args) {
    std::string input = "synthetic:subject=scan,distance=0.7,seed=1";
    int frames = 150;
    int every = 30;
    int stride = 2;
    float snapshot_error_m = 0.2e-3f;
    int repeat = 5;
    bool json = false;
    bool sweep = false;
    for (size_t i = 0; i < args.size(); ++i) {
        const std::string& a = args[i];
        const bool has_value = i + 1 < args.size();
        if (a == "--json") {
            json = true;
        } else if (a == "--sweep") {
            sweep = true;
        } else if (a == "--input" && has_value) {
            input = args[++i];
        } else if (a == "--frames" && has_value) {
            frames = std::max(1, std::stoi(args[++i]));
        } else if (a == "--snapshot-every" && has_value) {
            every = std::max(1, std::stoi(args[++i]));
        } else if (a == "--repeat" && has_value) {
            repeat = std::max(1, std::stoi(args[++i]));
        } else {
            std::printf(
                "usage: facescan-bench mesh [--input SRC] [--frames N] [--snapshot-every F] [--repeat R] [--sweep]\n"
                "                          [--json]\n"
                "The meshes facescan delivers, on the demo's scan (default SRC %s, 150 frames):\n"
                "live snapshots every F frames (30 = 1 Hz at 30 Hz; copy, incremental marching cubes at stride 2,\n"
                "Draco at 0.2 mm) and their share of a core per session; the final mesh's Draco size, encode and\n"
                "decode ms (mean of R), position error, defects, and the old wire (normals sent) as a baseline.\n"
                "--sweep: the final mesh's size and times at every Draco speed, with and without colours.\n",
                input.c_str());
            return a == "--help" ? 0 : 2;
        }
    }
    Sequence seq;
    if (const Status s = loadSequence(input, frames, seq); !s.isOk()) {
        std::fprintf(stderr, "mesh: %s\n", s.toString().c_str());
        return 1;
    }
    const recon::ReconParams params = recon::ReconParams::faceDefaults();
    recon::Reconstructor rec(seq.k, params);
    auto pipeline = recon::FacePipeline::create({}, seq.k, recon::ColourCamera::registeredTo(seq.k));
    if (!rec.initStatus().isOk() || !pipeline.isOk()) {
        std::fprintf(stderr, "mesh: cannot build the reconstructor or the face pipeline\n");
        return 1;
    }
    recon::MeshParams snap_params = params.mesh;
    snap_params.stride_vox = stride;
    recon::IncrementalMesher mesher(snap_params);
    wire::MeshCodecParams snap_codec;
    snap_codec.max_position_error_m = snapshot_error_m;
    recon::TsdfSnapshot grid, scratch;
    recon::ScanStep step;
    SnapshotFigures sf;
    std::vector<uint8_t> bytes;
    for (size_t i = 0; i < seq.frames.size(); ++i) {
        recon::scanFrame(*pipeline, rec, seq.frames[i], step);
        if ((i + 1) % static_cast<size_t>(every) != 0 || rec.framesIntegrated() == 0) continue;
        double t0 = threadMs();
        rec.copyVolume(grid);
        const double copy_ms = threadMs() - t0;
        grid.copyTo(scratch);  // for the full re-mesh beside it (update() swaps `grid` away)
        snap_codec.lattice_step_m = scratch.voxel_size_m;
        snap_codec.lattice_origin_m = scratch.origin_world;
        t0 = threadMs();
        const recon::IndexedMesh m = mesher.update(grid);
        const double mesh_ms = threadMs() - t0;
        t0 = threadMs();
        const recon::IndexedMesh full = recon::extractTriangles(scratch, snap_params);
        sf.full_mesh_ms += threadMs() - t0;
        sf.equal_to_full &= full.triangleCount() == m.triangleCount() && full.vertexCount() == m.vertexCount();
        {  // the old snapshot path (normals sent), on the same volume
            wire::MeshCodecParams old_codec;
            old_codec.max_position_error_m = snapshot_error_m;
            old_codec.normal_bits = 10;
            old_codec.speed = 7;
            t0 = threadMs();
            const recon::Mesh old_mesh = recon::extractMesh(scratch, snap_params);
            sf.old_mesh_ms += threadMs() - t0;
            t0 = threadMs();
            (void)wire::encodeMeshDraco(old_mesh, old_codec, bytes);
            sf.old_encode_ms += threadMs() - t0;
        }
        t0 = threadMs();
        if (m.triangles.empty() || !wire::encodeMeshDraco(m, snap_codec, bytes).isOk()) continue;
        const double encode_ms = threadMs() - t0;
        ++sf.count;
        sf.copy_ms += copy_ms, sf.mesh_ms += mesh_ms, sf.encode_ms += encode_ms;
        sf.max_total_ms = std::max(sf.max_total_ms, copy_ms + mesh_ms + encode_ms);
        const auto& st = mesher.lastStats();
        sf.blocks += st.blocks, sf.changed += st.blocks_changed, sf.remeshed += st.blocks_remeshed;
        sf.triangles += double(m.triangleCount()), sf.bytes += double(bytes.size());
    }
    const double n = std::max(1, sf.count);
    const double total_ms = (sf.copy_ms + sf.mesh_ms + sf.encode_ms) / n;
    const double period_s = every / 30.0;
    const double cpu_share = total_ms / (period_s * 1e3);
    std::printf("\nsnapshots: %d (every %d frames = %.2f s at 30 Hz), stride %d, Draco at %.2f mm\n", sf.count, every,
                period_s, stride, 1e3 * snapshot_error_m);
    std::printf("  mean per snapshot: copy %.2f ms, mesh %.2f ms (full re-mesh %.2f ms), encode %.2f ms\n",
                sf.copy_ms / n, sf.mesh_ms / n, sf.full_mesh_ms / n, sf.encode_ms / n);
    std::printf("  blocks %.0f, changed %.0f, re-meshed %.0f; %.0f triangles, %.1f KB\n", sf.blocks / n, sf.changed / n,
                sf.remeshed / n, sf.triangles / n, sf.bytes / n / 1024.0);
    std::printf(
        "  old wire, normals sent (same volumes): mesh %.2f ms (OpenMesh, gradient normals), encode %.2f ms "
        "(normals)\n",
        sf.old_mesh_ms / n, sf.old_encode_ms / n);
    std::printf("  copy+mesh+encode %.2f ms per snapshot (max %.2f) = %.2f %% of a core per session%s\n", total_ms,
                sf.max_total_ms, 100.0 * cpu_share, sf.equal_to_full ? "" : "  (INCREMENTAL != FULL)");

    recon::TsdfSnapshot final_grid;
    rec.copyVolume(final_grid);
    double t0 = threadMs();
    const recon::IndexedMesh final_mesh = recon::extractTriangles(final_grid, params.mesh);
    const double extract_ms = threadMs() - t0;
    FinalFigures ff;
    wire::MeshCodecParams final_codec;  // what the server sends: the quantisation grid on the voxel lines
    final_codec.lattice_step_m = final_grid.voxel_size_m;
    final_codec.lattice_origin_m = final_grid.origin_world;
    if (final_mesh.triangles.empty() || !measureFinal(final_mesh, final_codec, repeat, ff)) {
        std::fprintf(stderr, "mesh: the final mesh is empty or its round trip failed\n");
        return 1;
    }
    std::printf("\nfinal mesh: %zu triangles, %zu vertices extracted in %.1f ms; as delivered %zu triangles\n",
                final_mesh.triangleCount(), final_mesh.vertexCount(), extract_ms, ff.triangles);
    std::printf("  %-34s %10s %10s %10s %14s\n", "wire", "KB", "encode_ms", "decode_ms", "max_error_mm");
    std::printf("  %-34s %10.1f %10.2f %10.2f %14.4f\n", "positions+colours, arrays (now)", ff.bytes / 1024.0,
                ff.encode_ms, ff.decode_ms, ff.max_error_mm);
    std::printf("  %-34s %10.1f\n", "same, grid not on the voxel lines", ff.unaligned_bytes / 1024.0);
    std::printf("  %-34s %10.1f %10.2f %10.2f\n", "+10-bit normals, OpenMesh (before)", ff.old_bytes / 1024.0,
                ff.old_encode_ms, ff.old_decode_ms);
    std::printf("  decoded mesh to binary PLY bytes: %.2f ms\n", ff.write_ply_ms);
    std::printf("\n  %-34s %10s %10s %12s %10s %10s\n", "defects", "zero_area", "dup_tris", "unref_verts", "nm_edges",
                "nm_verts");
    printDefects("marching cubes output (raw)", ff.raw);
    printDefects("decoded by a client (delivered)", ff.delivered);
    if (sweep) printSweep(final_mesh, final_codec);
    const bool ok = ff.delivered.clean() && sf.equal_to_full;
    if (json) {
        std::printf(
            "{\"mesh\":{\"bytes\":%zu,\"encode_ms\":%.3f,\"decode_ms\":%.3f,\"max_error_mm\":%.5f,\"triangles\":%zu,"
            "\"unaligned_bytes\":%zu,\"old_bytes\":%zu,\"old_encode_ms\":%.3f,\"old_decode_ms\":%.3f,\"raw_defects\":%"
            "s,\"defects\":%s},"
            "\"snapshot\":{\"count\":%d,\"copy_ms\":%.3f,\"mesh_ms\":%.3f,\"full_mesh_ms\":%.3f,\"encode_ms\":%.3f,"
            "\"old_mesh_ms\":%.3f,\"old_encode_ms\":%.3f,\"cpu_share\":%.5f,\"blocks_changed_share\":%.3f}}\n",
            ff.bytes, ff.encode_ms, ff.decode_ms, ff.max_error_mm, ff.triangles, ff.unaligned_bytes, ff.old_bytes,
            ff.old_encode_ms, ff.old_decode_ms, jsonDefects(ff.raw).c_str(), jsonDefects(ff.delivered).c_str(),
            sf.count, sf.copy_ms / n, sf.mesh_ms / n, sf.full_mesh_ms / n, sf.encode_ms / n, sf.old_mesh_ms / n,
            sf.old_encode_ms / n, cpu_share, sf.blocks > 0 ? sf.changed / sf.blocks : 0.0);
    }
    return ok ? 0 : 1;
}

}  // namespace

FACESCAN_BENCH_COMMAND("mesh", "delivered meshes: snapshot cost, final mesh size/encode/decode/error, defects",
                       runMesh);

}  // namespace facescan::bench
