// Writes the fuzzers' seed corpus: a few small valid payloads of each kind, made with our own encoders.
// usage: facescan_fuzz_seeds OUT_DIR   ->  OUT_DIR/depth_<codec>/, OUT_DIR/colour_jpeg/, OUT_DIR/mesh_draco/
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>

#include "capture/ros_messages.hpp"
#include "sample_replica.hpp"
#include "test_data.hpp"
#include "wire/cluster_codec.hpp"
#include "wire/codecs.hpp"

namespace {

namespace fs = std::filesystem;
using namespace facescan::wire;

void writeFile(const fs::path& path, const std::vector<uint8_t>& bytes) {
    std::ofstream(path, std::ios::binary)
        .write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
}

// Small depth frames: a head-like dome before a wall, with holes; zeros; noise; a single pixel.
std::vector<cv::Mat> depthFrames() {
    std::vector<cv::Mat> frames;
    cv::Mat dome(12, 16, CV_16UC1);
    for (int v = 0; v < dome.rows; ++v) {
        for (int u = 0; u < dome.cols; ++u) {
            const double r2 = ((u - 8) * (u - 8) + (v - 6) * (v - 6)) / 25.0;
            dome.at<uint16_t>(v, u) = (u * 7 + v * 3) % 11 == 0 ? 0 : r2 < 1.0 ? uint16_t(650 + 40 * r2) : 1800;
        }
    }
    frames.push_back(dome);
    frames.push_back(cv::Mat::zeros(5, 7, CV_16UC1));
    cv::Mat noise(9, 9, CV_16UC1);
    cv::RNG(7).fill(noise, cv::RNG::UNIFORM, 0, 65536);
    frames.push_back(noise);
    frames.push_back(cv::Mat(1, 1, CV_16UC1, cv::Scalar(65535)));
    return frames;
}

facescan::recon::Mesh smallMesh(int n) {
    facescan::recon::Mesh mesh;
    std::vector<facescan::recon::Mesh::VertexHandle> vh;
    for (int j = 0; j < n; ++j) {
        for (int i = 0; i < n; ++i) {
            const float x = 0.01f * float(i);
            const float y = 0.01f * float(j);
            vh.push_back(mesh.add_vertex({x, y, 0.7f + 0.02f * std::sin(30.0f * x) * std::cos(20.0f * y)}));
        }
    }
    for (int j = 0; j + 1 < n; ++j) {
        for (int i = 0; i + 1 < n; ++i) {
            const size_t a = size_t(j) * n + i;
            mesh.add_face(vh[a], vh[a + 1], vh[a + n + 1]);
            mesh.add_face(vh[a], vh[a + n + 1], vh[a + n]);
        }
    }
    mesh.update_normals();
    for (const auto v : mesh.vertices()) mesh.set_color(v, {uint8_t(v.idx() * 7), uint8_t(v.idx() * 13), 128});
    return mesh;
}

}  // namespace

int main(int argc, char** argv) {
    if (argc != 2) {
        std::fprintf(stderr, "usage: %s OUT_DIR\n", argv[0]);
        return 2;
    }
    const fs::path out = argv[1];
    int written = 0;
    for (int c = 0; c < kDepthCodecCount; ++c) {
        DepthCodecParams params;
        params.codec = static_cast<DepthCodecId>(c);
        std::string name = depthCodecName(params.codec);
        for (char& ch : name) ch = ch == '-' ? '_' : ch;
        const fs::path dir = out / ("depth_" + name);
        fs::create_directories(dir);
        int i = 0;
        for (const cv::Mat& frame : depthFrames()) {
            std::vector<uint8_t> payload;
            if (!encodeDepth(frame, params, payload).isOk()) return 1;
            // Mode 0 (whole payload) and mode 1 (size bytes + body), see fuzz_depth.cpp.
            std::vector<uint8_t> whole{0};
            whole.insert(whole.end(), payload.begin(), payload.end());
            writeFile(dir / ("whole_" + std::to_string(i) + ".bin"), whole);
            std::vector<uint8_t> body{1, uint8_t(frame.cols - 1), uint8_t(frame.rows - 1)};
            body.insert(body.end(), payload.begin() + kDepthHeaderBytes, payload.end());
            writeFile(dir / ("body_" + std::to_string(i) + ".bin"), body);
            written += 2;
            ++i;
        }
    }
    fs::create_directories(out / "colour_jpeg");
    for (const int quality : {50, 90}) {
        for (const cv::Size size : {cv::Size(16, 16), cv::Size(33, 17)}) {
            cv::Mat bgr(size, CV_8UC3);
            cv::RNG(quality).fill(bgr, cv::RNG::UNIFORM, 0, 256);
            std::vector<uint8_t> jpeg;
            if (!encodeColourJpeg(bgr, quality, jpeg).isOk()) return 1;
            writeFile(out / "colour_jpeg" / ("q" + std::to_string(quality) + "_" + std::to_string(size.width) + ".jpg"),
                      jpeg);
            ++written;
        }
    }
    fs::create_directories(out / "mesh_draco");
    for (const int n : {3, 6}) {
        for (const int normal_bits : {0, 10}) {
            MeshCodecParams params;
            params.normal_bits = normal_bits;
            std::vector<uint8_t> drc;
            if (!encodeMeshDraco(smallMesh(n), params, drc).isOk()) return 1;
            writeFile(out / "mesh_draco" / ("grid" + std::to_string(n) + "_n" + std::to_string(normal_bits) + ".drc"),
                      drc);
            ++written;
        }
    }
    // The finished model with its texture coordinates (a finished session's GET_MESH): each vertex mapped by its
    // position, so the seed has a TEX_COORD attribute for the decoder to check.
    for (const int n : {3, 6}) {
        facescan::recon::TexturedMesh textured;
        textured.mesh = facescan::recon::fromOpenMesh(smallMesh(n));
        for (const Eigen::Vector3f& p : textured.mesh.positions_m) textured.uv.emplace_back(p.x() + 0.5f, p.y() + 0.5f);
        textured.atlas_bgr = cv::Mat(4, 4, CV_8UC3, cv::Scalar::all(128));
        std::vector<uint8_t> drc;
        if (!encodeTexturedMeshDraco(textured, {}, drc).isOk()) return 1;
        writeFile(out / "mesh_draco" / ("textured" + std::to_string(n) + ".drc"), drc);
        ++written;
    }
    // Replicas: whole (mode 0) and, for the body parser, the uncompressed body (mode 1) of a full and a delta.
    fs::create_directories(out / "replica");
    for (const bool full : {true, false}) {
        const ReplicaData r = facescan::testing::sampleReplica(2, full);
        std::vector<uint8_t> bytes;
        if (!encodeReplica(r, bytes).isOk()) return 1;
        std::vector<uint8_t> whole{0};
        whole.insert(whole.end(), bytes.begin(), bytes.end());
        writeFile(out / "replica" / (std::string(full ? "full" : "delta") + "_whole.bin"), whole);
        written += 1;
    }
    // Cluster messages: any bytes drive FuzzedDataProvider; a few fixed patterns start it off.
    fs::create_directories(out / "cluster_messages");
    for (int i = 0; i < 4; ++i) {
        std::vector<uint8_t> seed(64 + 32 * i);
        for (size_t k = 0; k < seed.size(); ++k) seed[k] = static_cast<uint8_t>("srv-a\0scan-1\0"[k % 14] + i);
        writeFile(out / "cluster_messages" / ("pattern" + std::to_string(i) + ".bin"), seed);
        ++written;
    }
    // The Azure Kinect calibration of a recording (its layout; the fixture's values, rounded), and variants.
    fs::create_directories(out / "azure_kinect_calibration");
    const std::string camera_rt = R"("Rt":{"Rotation":[1,0,0,0,1,0,0,0,1],"Translation":[0,0,0]})";
    const std::string calibration =
        R"({"CalibrationInformation":{"Cameras":[{"Intrinsics":{"ModelParameterCount":14,"ModelParameters":)"
        R"([0.513,0.517,0.493,0.493,0.548,-0.021,-0.0027,0.89,0.086,-0.014,0,0,-7.2E-5,2.1E-5],)"
        R"("ModelType":"CALIBRATION_LensDistortionModelBrownConrady"},"Location":"CALIBRATION_CameraLocationD0",)"
        R"("Purpose":"CALIBRATION_CameraPurposeDepth","MetricRadius":1.74,)" +
        camera_rt +
        R"(,"SensorHeight":1024,"SensorWidth":1024},{"Intrinsics":{"ModelParameterCount":14,"ModelParameters":)"
        R"([0.4998,0.5066,0.478,0.637,0.33,-2.49,1.45,0.209,-2.30,1.375,0,0,-1.3E-4,-1.6E-4],)"
        R"("ModelType":"CALIBRATION_LensDistortionModelBrownConrady"},"Location":"CALIBRATION_CameraLocationPV0",)"
        R"("Purpose":"CALIBRATION_CameraPurposePhotoVideo","MetricRadius":0,"Rt":{"Rotation":)"
        R"([0.99999922,0.00118,-0.000448,-0.001139,0.99628,0.08616,0.000548,-0.08616,0.99628],)"
        R"("Translation":[-0.0321,-0.0022,0.0039]},"SensorHeight":3072,"SensorWidth":4096}]}})";
    std::ofstream(out / "azure_kinect_calibration" / "two_cameras.json") << calibration;
    std::ofstream(out / "azure_kinect_calibration" / "depth_only.json")
        << calibration.substr(0, calibration.find(R"(,{"Intrinsics")")) << "]}}";
    written += 2;
    // The mkv reader: the head of the real recording (EBML header, tracks, the calibration attachment, tags and
    // the first, small cluster; the frames' megabytes are left out).
    fs::create_directories(out / "mkv");
    if (const auto data = facescan::testing::sharedData("azure_kinect_mkv")) {
        std::ifstream in(*data / "recording.mkv", std::ios::binary);
        std::vector<uint8_t> head(7546);
        in.read(reinterpret_cast<char*>(head.data()), static_cast<std::streamsize>(head.size()));
        head.resize(static_cast<size_t>(in.gcount()));
        writeFile(out / "mkv" / "azure_kinect_head.mkv", head);
        ++written;
    }
    // The bag reader: a tiny RealSense bag (16x12 depth and colour, two frames) in librealsense's layout.
    fs::create_directories(out / "bag");
    {
        namespace ros1 = facescan::capture::ros1;
        rosbag::Bag bag;
        bag.open((out / "bag" / "realsense_tiny.bag").string(), rosbag::bagmode::Write);
        const std::string depth = "/device_0/sensor_0/Depth_0", colour = "/device_0/sensor_1/Color_0";
        ros1::CameraInfo info;
        info.width = 16;
        info.height = 12;
        info.K = {14.0, 0, 7.5, 0, 14.0, 5.5, 0, 0, 1};
        bag.write(depth + "/info/camera_info", ros::Time(0, 1), info);
        bag.write(colour + "/info/camera_info", ros::Time(0, 1), info);
        ros1::Transform tf;
        tf.rotation.w = 1;
        tf.translation.x = 0.015;
        bag.write(colour + "/tf/0", ros::Time(0, 1), tf);
        ros1::Float32 units;
        units.data = 0.001f;
        bag.write("/device_0/sensor_0/option/Depth Units/value", ros::Time(0, 1), units);
        const cv::Mat dome = depthFrames().front();
        for (uint32_t n = 0; n < 2; ++n) {
            const ros::Time t(1, n * 33333333);
            ros1::Image d;
            d.header.stamp = t;
            d.width = 16;
            d.height = 12;
            d.encoding = "16UC1";
            d.step = 32;
            d.data.assign(dome.data, dome.data + dome.total() * 2);
            bag.write(depth + "/image/data", t, d);
            ros1::Image c = d;
            c.encoding = "rgb8";
            c.step = 48;
            c.data.assign(16 * 12 * 3, static_cast<uint8_t>(90 + n));
            bag.write(colour + "/image/data", t, c);
        }
        bag.close();
        ++written;
    }
    std::printf("wrote %d seeds under %s\n", written, out.c_str());
    return 0;
}
