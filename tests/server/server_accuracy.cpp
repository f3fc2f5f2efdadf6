// server_accuracy: measures a mesh (e.g. the server's final mesh.ply, or facescan-bench recon --mesh) against the
// synthetic subject of `facescan-agent --source synthetic[:frames=N]` with the project's ruler (facescan_eval),
// so the mesh fetched over DDS and the bench's mesh are judged by the same code. Not a test: a measuring tool
// for the server's accuracy figures. Usage: server_accuracy MESH [MESH...]  (default synthetic sequence parameters)
#include <cstdio>

#include "eval/accuracy.hpp"
#include "eval/mesh_io.hpp"
#include "synth/head_model.hpp"
#include "synth/kinect_simulator.hpp"

int main(int argc, char** argv) {
    using namespace facescan;
    if (argc < 2) {
        std::fprintf(stderr, "usage: server_accuracy MESH.ply [MESH.ply ...]\n");
        return 2;
    }
    const synth::KinectSimulator sim(synth::defaultHead(), synth::SequenceParams{});
    const recon::Mesh& gt = sim.head().mesh;
    const Eigen::Vector3f nose = eval::findNoseTip(gt);
    const recon::Pose guess = sim.poseAt(0).inverse();  // meshes are in the first camera frame
    int rc = 0;
    for (int i = 1; i < argc; ++i) {
        auto mesh = eval::readMesh(argv[i]);
        if (!mesh.isOk()) {
            std::fprintf(stderr, "%s: %s\n", argv[i], mesh.status().toString().c_str());
            rc = 1;
            continue;
        }
        auto acc = eval::measureAccuracy(*mesh, gt, nose, {}, guess);
        if (!acc.isOk()) {
            std::fprintf(stderr, "%s: %s\n", argv[i], acc.status().toString().c_str());
            rc = 1;
            continue;
        }
        std::printf(
            "%s: %zu faces, mean %.3f mm, rms %.3f mm, median %.3f mm, p90 %.3f mm, completeness %.3f; unaligned mean "
            "%.3f mm, uniform offset %+.3f mm\n",
            argv[i], mesh->n_faces(), acc->mean_mm, acc->rms_mm, acc->median_mm, acc->p90_mm, acc->completeness,
            acc->unaligned.mean_mm, acc->offset_mm);
    }
    return rc;
}
