// The files `facescan view` serves: our page (client_cli/web: index.html, viewer.js, style.css) and the parts of
// three.js it loads (from npm, node_modules/three). Read once at start and kept in memory, each also gzipped
// (the page's 2.5 MB of JavaScript and wasm are about 0.6 MB compressed, what a browser on Wi-Fi waits for).
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include "recon/status.hpp"

namespace facescan::client {

// One file: its URL, its path under the web root (the same layout in the source tree, after `npm ci` in
// client_cli/web, and installed in <prefix>/share/facescan/web), and its type.
struct WebAsset {
    const char* url;
    const char* path;
    const char* mime;
};
const std::vector<WebAsset>& webAssets();

// The asset folder: $FACESCAN_WEB_DIR, else web/ of the share/facescan folders (wire/data_files.hpp: beside the
// program's bin/ first), else the source tree's client_cli/web.
// NotFound, saying what to run, when none holds every asset (three.js is installed by deploy/install-deps.sh).
StatusOr<std::filesystem::path> findWebRoot();
// Whether `root` holds every asset; NotFound naming the first missing one and what to run.
Status checkWebRoot(const std::filesystem::path& root);

// An asset in memory, as sent.
struct LoadedAsset {
    std::string url;
    std::string mime;
    std::string identity;  // the file's bytes
    std::string gzip;      // the same, gzip-compressed (Content-Encoding: gzip)
    std::string etag;      // a quoted hash of the bytes, for If-None-Match
};
// Reads and compresses every asset under `root`. NotFound as checkWebRoot; Unavailable when a file cannot be read.
StatusOr<std::vector<LoadedAsset>> loadWebAssets(const std::filesystem::path& root);

}  // namespace facescan::client
