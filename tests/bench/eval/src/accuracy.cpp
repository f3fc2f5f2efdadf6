// The accuracy ruler (docs/design.md s6): rigid point-to-plane ICP of M onto G from several starting poses, then
// point-to-surface distances over G's face region, completeness (whole region and observed part) and outliers.
#include "eval/accuracy.hpp"

#include <Eigen/Cholesky>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <opencv2/core/utility.hpp>
#include <string>
#include <vector>

namespace facescan::eval {
namespace {

using Vec3 = Eigen::Vector3f;

// M's vertices and vertex normals (area-weighted from its triangles, whatever the file said).
struct Samples {
    std::vector<Vec3> points, normals;
};

Samples samplesOf(const recon::Mesh& mesh) {
    recon::Mesh m = mesh;
    m.update_face_normals();
    m.update_vertex_normals();
    Samples s;
    s.points.reserve(m.n_vertices());
    s.normals.reserve(m.n_vertices());
    for (const auto vh : m.vertices()) {
        const auto& p = m.point(vh);
        const auto& n = m.normal(vh);
        s.points.emplace_back(p[0], p[1], p[2]);
        s.normals.emplace_back(n[0], n[1], n[2]);
    }
    return s;
}

Samples subsample(const Samples& all, size_t count) {
    Samples out;
    const size_t stride = std::max<size_t>(1, all.points.size() / std::max<size_t>(1, count));
    for (size_t i = 0; i < all.points.size(); i += stride) {
        out.points.push_back(all.points[i]);
        out.normals.push_back(all.normals[i]);
    }
    return out;
}

// G's face region, as flags per vertex and per face (a face belongs when at least two corners do).
struct FaceRegion {
    std::vector<uint8_t> vertex, face;
    int vertex_count = 0;
};

FaceRegion faceRegion(const recon::Mesh& gt, const Vec3& nose, const Vec3& face_dir, const AccuracyParams& p) {
    FaceRegion r;
    r.vertex.assign(gt.n_vertices(), 0);
    r.face.assign(gt.n_faces(), 0);
    for (const auto vh : gt.vertices()) {
        const auto& q = gt.point(vh);
        const auto& n = gt.normal(vh);
        const bool in = (Vec3(q[0], q[1], q[2]) - nose).norm() <= p.face_radius_m &&
                        Vec3(n[0], n[1], n[2]).dot(face_dir) >= p.min_facing_cos;
        r.vertex[vh.idx()] = in;
        r.vertex_count += in;
    }
    for (const auto fh : gt.faces()) {
        int in = 0;
        for (const auto vh : gt.fv_range(fh)) in += r.vertex[vh.idx()];
        r.face[fh.idx()] = in >= 2;
    }
    return r;
}

// How a sample of M meets G: the nearest point on G (on the wall facing M's way when match_facing).
SurfaceDistance::Hit hitOf(const SurfaceDistance& gt_dist, const Vec3& p, const Vec3& n, bool match_facing) {
    return match_facing ? gt_dist.query(p, n) : gt_dist.query(p);
}

// Samples of M in the face region after transform T: |d| per sample (metres), computed in parallel.
std::vector<float> faceDistances(const Samples& m, const recon::Pose& T, const SurfaceDistance& gt_dist,
                                 const FaceRegion& region, bool match_facing) {
    std::vector<float> d(m.points.size(), -1.0f);
    cv::parallel_for_(cv::Range(0, static_cast<int>(m.points.size())), [&](const cv::Range& range) {
        for (int i = range.start; i < range.end; ++i) {
            const auto hit = hitOf(gt_dist, T * m.points[i], T.linear() * m.normals[i], match_facing);
            if (hit.face >= 0 && region.face[hit.face]) d[i] = hit.distance_m;
        }
    });
    std::vector<float> out;
    for (const float x : d) {
        if (x >= 0) out.push_back(x);
    }
    return out;
}

// Share of samples whose normal (moved by T) points the way of the G triangle nearest to them.
double facingAgreement(const Samples& m, const recon::Pose& T, const SurfaceDistance& gt_dist,
                       const FaceRegion& region) {
    int agree = 0, total = 0;
    for (size_t i = 0; i < m.points.size(); ++i) {
        const auto hit = gt_dist.query(T * m.points[i]);
        if (hit.face < 0 || !region.face[hit.face] || hit.distance_m > 0.01f) continue;
        ++total;
        agree += hit.normal.dot(T.linear() * m.normals[i]) > 0;
    }
    return total > 0 ? static_cast<double>(agree) / total : 1.0;
}

double percentile(std::vector<float> v, double q) {
    if (v.empty()) return 0;
    const size_t k = std::min(v.size() - 1, static_cast<size_t>(q * static_cast<double>(v.size() - 1) + 0.5));
    std::nth_element(v.begin(), v.begin() + static_cast<long>(k), v.end());
    return v[k];
}

DistanceFigures figuresOf(const std::vector<float>& d, float outlier_m) {
    DistanceFigures f;
    f.samples = static_cast<int>(d.size());
    if (d.empty()) return f;
    double sum = 0, ss = 0;
    int far = 0;
    for (const float x : d) {
        sum += x;
        ss += static_cast<double>(x) * x;
        far += x > outlier_m;
    }
    const auto n = static_cast<double>(d.size());
    f.mean_mm = 1000.0 * sum / n;
    f.rms_mm = 1000.0 * std::sqrt(ss / n);
    f.median_mm = 1000.0 * percentile(d, 0.5);
    f.p90_mm = 1000.0 * percentile(d, 0.9);
    f.outliers = static_cast<double>(far) / n;
    return f;
}

struct IcpResult {
    recon::Pose T = recon::Pose::Identity();
    double offset_m = 0;  // the uniform normal offset fitted alongside T (not applied)
    int inliers = 0;      // samples within 3 mm of G's face after alignment
    double rms_m = 1e9;   // of those inliers
};

// Point-to-plane ICP (the thesis' tracking metric, eq. 4.22, here between meshes): correspondences are the
// nearest points on G's face region; the gate shrinks from 50 mm to 10 mm so that far starts can converge.
// With fit_offset the residual of sample p against its G point q with normal n is n.(q - T p) + offset: a
// seventh unknown takes up a uniform inflation of M, so the rigid motion is estimated as if there were none.
// Iteratively reweighted (robust_scale_m): an L1 fit. Least squares let the crease and curvature tails of an
// offset surface pull the pose by 0.03-0.09 mm, enough to hide 5 % of a 1 mm inflation.
IcpResult runIcp(const Samples& samples, const SurfaceDistance& gt_dist, const FaceRegion& region, recon::Pose T,
                 int iterations, const AccuracyParams& params) {
    struct Corr {
        Vec3 p, q, n;
        bool ok;
    };
    using Vec7 = Eigen::Matrix<double, 7, 1>;
    using Mat7 = Eigen::Matrix<double, 7, 7>;
    const int unknowns = params.fit_offset ? 7 : 6;
    std::vector<Corr> corr(samples.points.size());
    double offset_m = 0;
    for (int it = 0; it < iterations; ++it) {
        const float gate = std::max(0.01f, 0.05f * std::pow(0.85f, static_cast<float>(it)));
        cv::parallel_for_(cv::Range(0, static_cast<int>(corr.size())), [&](const cv::Range& range) {
            for (int i = range.start; i < range.end; ++i) {
                const Vec3 p = T * samples.points[i];
                const auto hit = hitOf(gt_dist, p, T.linear() * samples.normals[i], params.match_facing);
                corr[i] = {p, hit.closest, hit.normal, hit.face >= 0 && region.face[hit.face] && hit.distance_m < gate};
            }
        });
        Mat7 A = Mat7::Zero();
        Vec7 b = Vec7::Zero();
        int n_ok = 0;
        for (const Corr& c : corr) {
            if (!c.ok) continue;
            Vec7 J;
            J.head<3>() = c.p.cross(c.n).cast<double>();
            J.segment<3>(3) = c.n.cast<double>();
            J(6) = -1.0;
            const double r = static_cast<double>((c.q - c.p).dot(c.n));
            const double e = std::abs(r + offset_m);  // what the offset does not explain
            const double w = e > params.robust_scale_m && params.robust_scale_m > 0 ? params.robust_scale_m / e : 1.0;
            A += w * J * J.transpose();
            b += w * J * r;
            ++n_ok;
        }
        if (n_ok < unknowns) break;
        Vec7 x = Vec7::Zero();
        if (params.fit_offset) {
            // A whisper of damping on the offset: where the surface cannot tell it from a translation (a flat
            // patch), it stays near 0 instead of trading off against the translation.
            A(6, 6) += 1e-4 * n_ok;
            x = A.ldlt().solve(b);
        } else {
            x.head<6>() = A.topLeftCorner<6, 6>().ldlt().solve(b.head<6>());
        }
        if (!x.allFinite()) break;
        offset_m = x(6);
        recon::Pose dT = recon::Pose::Identity();
        const Eigen::Vector3d w = x.head<3>();
        if (w.norm() > 0) dT.linear() = Eigen::AngleAxisd(w.norm(), w.normalized()).toRotationMatrix().cast<float>();
        dT.translation() = x.segment<3>(3).cast<float>();
        T = dT * T;
        if (w.norm() < 1e-6 && x.segment<3>(3).norm() < 1e-7 && gate <= 0.0101f) break;
    }
    IcpResult res;
    res.T = T;
    res.offset_m = offset_m;
    const std::vector<float> d = faceDistances(samples, T, gt_dist, region, params.match_facing);
    double ss = 0;
    for (const float x : d) {
        // Inliers and their spread are counted around the fitted offset: an inflated mesh is not a worse fit.
        const double e = std::abs(static_cast<double>(x) - std::abs(offset_m));
        if (e < 0.003) ++res.inliers, ss += e * e;
    }
    res.rms_m = res.inliers > 0 ? std::sqrt(ss / res.inliers) : 1e9;
    return res;
}

}  // namespace

Status AccuracyParams::validate() const {
    if (!(face_radius_m > 0.01f && face_radius_m < 1.0f)) return invalidArgument("accuracy: face radius 0.01-1 m");
    if (!(min_facing_cos >= -1 && min_facing_cos <= 1)) return invalidArgument("accuracy: facing cosine in [-1, 1]");
    if (!(complete_within_m > 0 && outlier_m > 0)) return invalidArgument("accuracy: thresholds must be > 0");
    if (icp_iterations < 0 || icp_iterations > 1000) return invalidArgument("accuracy: ICP iterations 0-1000");
    if (max_icp_samples < 100) return invalidArgument("accuracy: at least 100 ICP samples");
    if (!(robust_scale_m >= 0 && robust_scale_m < 0.01f)) return invalidArgument("accuracy: robust scale 0-10 mm");
    return Status::ok();
}

std::string accuracyJson(const AccuracyReport& r) {
    const DistanceFigures& u = r.unaligned;
    char buf[512];
    std::snprintf(
        buf, sizeof buf,
        "{\"mean_mm\":%.4f,\"rms_mm\":%.4f,\"median_mm\":%.4f,\"p90_mm\":%.4f,\"completeness\":%.5f,"
        "\"completeness_observed\":%.5f,\"observable_share\":%.5f,\"outliers\":%.5f,\"mesh_vertices_used\":%d,"
        "\"offset_mm\":%.4f,\"unaligned\":{\"mean_mm\":%.4f,\"rms_mm\":%.4f,\"median_mm\":%.4f,"
        "\"p90_mm\":%.4f,\"outliers\":%.5f,\"samples\":%d}}",
        r.mean_mm, r.rms_mm, r.median_mm, r.p90_mm, r.completeness, r.completeness_observed,
        r.gt_face_vertices > 0 ? static_cast<double>(r.gt_observed_vertices) / r.gt_face_vertices : 0.0, r.outliers,
        r.mesh_vertices_used, r.offset_mm, u.mean_mm, u.rms_mm, u.median_mm, u.p90_mm, u.outliers, u.samples);
    return buf;
}

recon::Mesh offsetAlongNormals(const recon::Mesh& mesh, float offset_m) {
    recon::Mesh out = mesh;
    for (const auto vh : out.vertices()) out.point(vh) += offset_m * out.normal(vh);
    out.update_normals();
    return out;
}

Eigen::Vector3f findNoseTip(const recon::Mesh& gt) {
    float y_min = std::numeric_limits<float>::max(), y_max = -y_min;
    for (const auto vh : gt.vertices()) {
        y_min = std::min(y_min, gt.point(vh)[1]);
        y_max = std::max(y_max, gt.point(vh)[1]);
    }
    // The chest of a bust may stick out further than the nose; the upper 60 % of the height is the head.
    const float y_floor = y_min + 0.4f * (y_max - y_min);
    Vec3 best(0, 0, -std::numeric_limits<float>::max());
    for (const auto vh : gt.vertices()) {
        const auto& p = gt.point(vh);
        if (p[1] >= y_floor && p[2] > best.z()) best = Vec3(p[0], p[1], p[2]);
    }
    return best;
}

StatusOr<AccuracyReport> measureAccuracy(const recon::Mesh& mesh, const recon::Mesh& gt, const Vec3& gt_nose_tip,
                                         const AccuracyParams& params, const std::optional<recon::Pose>& guess,
                                         const Vec3& face_direction) {
    RETURN_IF_ERROR(params.validate());
    if (mesh.n_vertices() == 0) return invalidArgument("accuracy: the mesh has no vertices");
    if (gt.n_faces() == 0 || !gt.has_vertex_normals()) return invalidArgument("accuracy: GT needs faces and normals");
    if (!gt_nose_tip.allFinite() || face_direction.norm() < 0.5f) return invalidArgument("accuracy: bad nose/facing");
    const Vec3 face_dir = face_direction.normalized();
    const FaceRegion region = faceRegion(gt, gt_nose_tip, face_dir, params);
    if (region.vertex_count == 0) return invalidArgument("accuracy: no GT vertex in the face region");
    if (!params.observed.empty() && params.observed.size() != gt.n_vertices())
        return invalidArgument("accuracy: the observed mask has " + std::to_string(params.observed.size()) +
                               " entries for " + std::to_string(gt.n_vertices()) + " GT vertices");
    int observed_face = region.vertex_count;
    if (!params.observed.empty()) {
        observed_face = 0;
        for (size_t i = 0; i < params.observed.size(); ++i) observed_face += region.vertex[i] && params.observed[i];
        if (observed_face == 0) return invalidArgument("accuracy: the observed mask marks no GT face vertex");
    }
    const SurfaceDistance gt_dist(gt);
    Samples all = samplesOf(mesh);
    const std::vector<Vec3>& pts = all.points;

    const recon::Pose T_given = guess.value_or(recon::Pose::Identity());
    recon::Pose best_T = T_given;
    double offset_m = 0;
    if (params.align) {
        // Starting poses: the guess, then M turned four ways with its most forward point put on G's nose tip
        // (a mesh in camera coordinates faces -z, one in head coordinates +z).
        std::vector<recon::Pose> starts;
        if (guess) starts.push_back(*guess);
        const Eigen::Matrix3f flips[] = {Eigen::Vector3f(1, -1, -1).asDiagonal(), Eigen::Matrix3f::Identity(),
                                         Eigen::Vector3f(-1, 1, -1).asDiagonal(),
                                         Eigen::Vector3f(-1, -1, 1).asDiagonal()};
        for (const auto& R : flips) {
            Vec3 tip = R * pts[0];
            for (const auto& p : pts) {
                if ((R * p).dot(face_dir) > tip.dot(face_dir)) tip = R * p;
            }
            recon::Pose T = recon::Pose::Identity();
            T.linear() = R;
            T.translation() = gt_nose_tip - tip;
            starts.push_back(T);
        }
        // Coarse: every start with a few samples and plain nearest points (M's normals may point inwards);
        // fine: the winner with all ICP samples.
        const Samples coarse = subsample(all, 1500);
        AccuracyParams coarse_params = params;
        coarse_params.match_facing = false;
        IcpResult best;
        best.inliers = -1;
        for (const auto& start : starts) {
            const IcpResult r = runIcp(coarse, gt_dist, region, start, params.icp_iterations / 2 + 1, coarse_params);
            if (r.inliers > best.inliers || (r.inliers == best.inliers && r.rms_m < best.rms_m)) best = r;
        }
        // A mesh whose triangles wind the other way has inward normals: turn them round before matching walls.
        if (params.match_facing && facingAgreement(coarse, best.T, gt_dist, region) < 0.5) {
            for (Vec3& n : all.normals) n = -n;
        }
        best = runIcp(subsample(all, static_cast<size_t>(params.max_icp_samples)), gt_dist, region, best.T,
                      params.icp_iterations, params);
        best_T = best.T;
        offset_m = best.offset_m;
    }

    const std::vector<float> d = faceDistances(all, best_T, gt_dist, region, params.match_facing);
    if (d.empty()) return notFound("accuracy: no vertex of the mesh lies over the GT face region");
    AccuracyReport rep;
    rep.T_gt_mesh = best_T;
    rep.offset_mm = 1000.0 * offset_m;
    rep.mesh_vertices_used = static_cast<int>(d.size());
    rep.gt_face_vertices = region.vertex_count;
    const DistanceFigures aligned = figuresOf(d, params.outlier_m);
    rep.mean_mm = aligned.mean_mm;
    rep.rms_mm = aligned.rms_mm;
    rep.median_mm = aligned.median_mm;
    rep.p90_mm = aligned.p90_mm;
    rep.outliers = aligned.outliers;
    rep.unaligned = params.align
                        ? figuresOf(faceDistances(all, T_given, gt_dist, region, params.match_facing), params.outlier_m)
                        : aligned;

    // Completeness: G's face vertices within complete_within_m of M's surface (M moved into G's frame).
    recon::Mesh moved = mesh;
    for (const auto vh : moved.vertices()) {
        const Vec3 p = best_T * pts[vh.idx()];
        moved.point(vh) = recon::Mesh::Point(p.x(), p.y(), p.z());
    }
    const SurfaceDistance mesh_dist(moved);
    std::vector<int> gt_face_ids;
    for (const auto vh : gt.vertices()) {
        if (region.vertex[vh.idx()]) gt_face_ids.push_back(vh.idx());
    }
    std::vector<uint8_t> covered(gt_face_ids.size(), 0);
    cv::parallel_for_(cv::Range(0, static_cast<int>(gt_face_ids.size())), [&](const cv::Range& range) {
        for (int i = range.start; i < range.end; ++i) {
            const auto& q = gt.point(recon::Mesh::VertexHandle(gt_face_ids[i]));
            covered[i] = mesh_dist.query(Vec3(q[0], q[1], q[2])).distance_m <= params.complete_within_m;
        }
    });
    rep.completeness =
        static_cast<double>(std::count(covered.begin(), covered.end(), 1)) / static_cast<double>(gt_face_ids.size());
    // The same test over the observed part of the region only (all of it when no mask was given).
    int covered_observed = 0;
    for (size_t i = 0; i < gt_face_ids.size(); ++i) {
        covered_observed += covered[i] && (params.observed.empty() || params.observed[gt_face_ids[i]]);
    }
    rep.gt_observed_vertices = observed_face;
    rep.completeness_observed = static_cast<double>(covered_observed) / static_cast<double>(observed_face);
    return rep;
}

}  // namespace facescan::eval
