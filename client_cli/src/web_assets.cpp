// The viewer's files (client/web_assets.hpp): where they are, and in memory with their gzip.
#include "client/web_assets.hpp"

#include <zlib.h>

#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <functional>
#include <sstream>

#include "wire/data_files.hpp"

namespace facescan::client {
namespace fs = std::filesystem;

namespace {

constexpr const char* kInstallHint =
    "run deploy/install-deps.sh (it installs three.js with `npm ci` in client_cli/web), or `cmake --install` "
    "facescan, or point FACESCAN_WEB_DIR at a folder with the viewer's files";

// gzip (RFC 1952) at zlib's default level: a few tens of ms for all assets, once at start.
StatusOr<std::string> gzipped(const std::string& bytes) {
    z_stream z{};
    if (deflateInit2(&z, Z_DEFAULT_COMPRESSION, Z_DEFLATED, 15 + 16, 8, Z_DEFAULT_STRATEGY) != Z_OK) {
        return internalError("zlib: deflateInit2 failed");
    }
    std::string out(deflateBound(&z, bytes.size()), '\0');
    z.next_in = reinterpret_cast<Bytef*>(const_cast<char*>(bytes.data()));
    z.avail_in = static_cast<uInt>(bytes.size());
    z.next_out = reinterpret_cast<Bytef*>(out.data());
    z.avail_out = static_cast<uInt>(out.size());
    const int rc = deflate(&z, Z_FINISH);
    out.resize(z.total_out);
    deflateEnd(&z);
    if (rc != Z_STREAM_END) return internalError("zlib: deflate failed");
    return out;
}

}  // namespace

const std::vector<WebAsset>& webAssets() {
    static const std::vector<WebAsset> assets = {
        {"/", "index.html", "text/html; charset=utf-8"},
        {"/index.html", "index.html", "text/html; charset=utf-8"},
        {"/viewer.js", "viewer.js", "text/javascript; charset=utf-8"},
        {"/style.css", "style.css", "text/css; charset=utf-8"},
        {"/vendor/three.module.js", "node_modules/three/build/three.module.js", "text/javascript; charset=utf-8"},
        {"/vendor/three.core.js", "node_modules/three/build/three.core.js", "text/javascript; charset=utf-8"},
        {"/vendor/addons/controls/OrbitControls.js", "node_modules/three/examples/jsm/controls/OrbitControls.js",
         "text/javascript; charset=utf-8"},
        {"/vendor/addons/loaders/DRACOLoader.js", "node_modules/three/examples/jsm/loaders/DRACOLoader.js",
         "text/javascript; charset=utf-8"},
        {"/vendor/draco/draco_wasm_wrapper.js", "node_modules/three/examples/jsm/libs/draco/draco_wasm_wrapper.js",
         "text/javascript; charset=utf-8"},
        {"/vendor/draco/draco_decoder.wasm", "node_modules/three/examples/jsm/libs/draco/draco_decoder.wasm",
         "application/wasm"},
    };
    return assets;
}

Status checkWebRoot(const fs::path& root) {
    std::error_code ec;
    for (const WebAsset& asset : webAssets()) {
        if (!fs::is_regular_file(root / asset.path, ec)) {
            return notFound("the viewer's file '" + (root / asset.path).string() + "' is missing: " + kInstallHint);
        }
    }
    return Status::ok();
}

StatusOr<fs::path> findWebRoot() {
    if (const char* env = std::getenv("FACESCAN_WEB_DIR"); env && *env) {
        RETURN_IF_ERROR(checkWebRoot(env));
        return fs::path(env);
    }
    // share/facescan/web of the installed tree (beside bin/) or a configured prefix (wire/data_files.hpp), then the
    // source tree's folder (where npm ci put three.js).
    std::vector<fs::path> candidates;
    std::error_code ec;
    for (const fs::path& share : wire::shareDirs()) candidates.push_back(share / "web");
#ifdef FACESCAN_WEB_SOURCE_DIR
    candidates.emplace_back(FACESCAN_WEB_SOURCE_DIR);
#endif
    Status first_missing = notFound(std::string("no folder with the viewer's files: ") + kInstallHint);
    for (const fs::path& dir : candidates) {
        if (!fs::is_directory(dir, ec)) continue;
        const Status s = checkWebRoot(dir);
        if (s.isOk()) return fs::weakly_canonical(dir, ec);
        first_missing = s;
    }
    return first_missing;
}

StatusOr<std::vector<LoadedAsset>> loadWebAssets(const fs::path& root) {
    RETURN_IF_ERROR(checkWebRoot(root));
    std::vector<LoadedAsset> loaded;
    for (const WebAsset& asset : webAssets()) {
        std::ifstream in(root / asset.path, std::ios::binary);
        std::ostringstream bytes;
        bytes << in.rdbuf();
        if (!in) return unavailable("cannot read the viewer's file '" + (root / asset.path).string() + "'");
        LoadedAsset a;
        a.url = asset.url;
        a.mime = asset.mime;
        a.identity = std::move(bytes).str();
        ASSIGN_OR_RETURN(a.gzip, gzipped(a.identity));
        char etag[24];
        std::snprintf(etag, sizeof(etag), "\"%016zx\"", std::hash<std::string>{}(a.identity));
        a.etag = etag;
        loaded.push_back(std::move(a));
    }
    return loaded;
}

}  // namespace facescan::client
