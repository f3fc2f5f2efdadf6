// Depth image to triangle mesh (pixel grid triangulation), for the single-frame accuracy baseline.
#include "eval/depth_mesh.hpp"

#include <vector>

namespace facescan::eval {

recon::Mesh meshFromDepth(const cv::Mat& depth_m, const recon::Intrinsics& k, const cv::Mat& mask, float max_edge_m) {
    recon::Mesh mesh;
    if (depth_m.type() != CV_32FC1 || (!mask.empty() && (mask.type() != CV_8UC1 || mask.size() != depth_m.size()))) {
        return mesh;
    }
    std::vector<int> index(depth_m.total(), -1);
    std::vector<Eigen::Vector3f> pts;
    for (int v = 0; v < depth_m.rows; ++v) {
        for (int u = 0; u < depth_m.cols; ++u) {
            const float z = depth_m.at<float>(v, u);
            if (!(z > 0) || (!mask.empty() && mask.at<uint8_t>(v, u) == 0)) continue;
            const Eigen::Vector3f p = k.backProject(static_cast<float>(u), static_cast<float>(v), z);
            index[v * depth_m.cols + u] = static_cast<int>(pts.size());
            pts.push_back(p);
            mesh.add_vertex(recon::Mesh::Point(p.x(), p.y(), p.z()));
        }
    }
    const float max2 = max_edge_m * max_edge_m;
    auto tri = [&](int a, int b, int c) {
        if (a < 0 || b < 0 || c < 0) return;
        if ((pts[a] - pts[b]).squaredNorm() > max2 || (pts[b] - pts[c]).squaredNorm() > max2 ||
            (pts[c] - pts[a]).squaredNorm() > max2) {
            return;
        }
        // Image rows grow downwards, so (a, c, b) winds counter-clockwise seen from the camera.
        mesh.add_face(recon::Mesh::VertexHandle(a), recon::Mesh::VertexHandle(c), recon::Mesh::VertexHandle(b));
    };
    for (int v = 0; v + 1 < depth_m.rows; ++v) {
        for (int u = 0; u + 1 < depth_m.cols; ++u) {
            const int i00 = index[v * depth_m.cols + u], i01 = index[v * depth_m.cols + u + 1];
            const int i10 = index[(v + 1) * depth_m.cols + u], i11 = index[(v + 1) * depth_m.cols + u + 1];
            tri(i00, i01, i11);
            tri(i00, i11, i10);
        }
    }
    mesh.update_face_normals();
    mesh.update_vertex_normals();
    return mesh;
}

}  // namespace facescan::eval
