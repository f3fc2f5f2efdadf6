// Writes a synthetic sequence as a TUM RGB-D folder (docs/design.md s7) with its ground truth.
#include <OpenMesh/Core/IO/MeshIO.hh>
#include <cstdio>
#include <fstream>
#include <iomanip>
#include <opencv2/imgcodecs.hpp>

#include "synth/kinect_simulator.hpp"

namespace facescan::synth {

Status writeTumSequence(const KinectSimulator& simulator, const std::filesystem::path& dir) {
    namespace fs = std::filesystem;
    std::error_code ec;
    fs::create_directories(dir / "rgb", ec);
    fs::create_directories(dir / "depth", ec);
    if (ec) return unavailable("cannot create " + dir.string() + ": " + ec.message());
    std::ofstream rgb_txt(dir / "rgb.txt"), depth_txt(dir / "depth.txt"), gt_txt(dir / "groundtruth.txt");
    std::ofstream intrinsics_txt(dir / "intrinsics.txt"), pose_txt(dir / "T_camera0_head.txt");
    if (!rgb_txt || !depth_txt || !gt_txt || !intrinsics_txt || !pose_txt) {
        return unavailable("cannot write the index files in " + dir.string());
    }
    for (auto* f : {&rgb_txt, &depth_txt, &gt_txt}) *f << std::fixed << std::setprecision(6);
    rgb_txt << "# colour images (registered to depth)\n# timestamp filename\n";
    depth_txt << "# depth images, 16-bit PNG, 5000 units per metre\n# timestamp filename\n";
    gt_txt << "# camera i in the first camera's frame (the head is static there)\n# timestamp tx ty tz qx qy qz qw\n";
    const recon::Intrinsics& k = simulator.intrinsics();
    intrinsics_txt << std::setprecision(9) << k.fx_px << ' ' << k.fy_px << ' ' << k.cx_px << ' ' << k.cy_px << '\n';

    const recon::Pose T_camera0_head = simulator.poseAt(0);
    pose_txt << std::setprecision(9);
    for (int r = 0; r < 4; ++r) {
        for (int c = 0; c < 4; ++c) pose_txt << T_camera0_head.matrix()(r, c) << (c == 3 ? '\n' : ' ');
    }
    recon::RgbdFrame frame;
    cv::Mat raw;
    for (int i = 0; i < simulator.frameCount(); ++i) {
        simulator.render(i, frame);
        const double t = static_cast<double>(frame.timestamp_ns) * 1e-9;
        char name[64];
        std::snprintf(name, sizeof name, "%.6f.png", t);
        recon::depthMetresToRaw(frame.depth_m, 1.0f / 5000.0f, raw);
        if (!cv::imwrite((dir / "depth" / name).string(), raw) ||
            !cv::imwrite((dir / "rgb" / name).string(), frame.colour_bgr)) {
            return unavailable("cannot write frame " + std::to_string(i) + " in " + dir.string());
        }
        rgb_txt << t << " rgb/" << name << '\n';
        depth_txt << t << " depth/" << name << '\n';
        // The head is fixed in the reference frame; the camera moves around it: T_c0_ci = T_c0_h * T_ci_h^-1.
        const recon::Pose T_c0_ci = T_camera0_head * simulator.poseAt(i).inverse();
        const Eigen::Quaternionf q(T_c0_ci.linear());
        const Eigen::Vector3f p = T_c0_ci.translation();
        gt_txt << t << ' ' << p.x() << ' ' << p.y() << ' ' << p.z() << ' ' << q.x() << ' ' << q.y() << ' ' << q.z()
               << ' ' << q.w() << '\n';
    }
    OpenMesh::IO::Options opts =
        OpenMesh::IO::Options::Binary | OpenMesh::IO::Options::VertexNormal | OpenMesh::IO::Options::VertexColor;
    if (!OpenMesh::IO::write_mesh(simulator.head().mesh, (dir / "head_gt.ply").string(), opts)) {
        return unavailable("cannot write " + (dir / "head_gt.ply").string());
    }
    if (!rgb_txt.flush() || !depth_txt.flush() || !gt_txt.flush())
        return unavailable("write failed in " + dir.string());
    return Status::ok();
}

}  // namespace facescan::synth
