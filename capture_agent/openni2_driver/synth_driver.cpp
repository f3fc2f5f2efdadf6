// The OpenNI2 driver entry points of libFacescanSynth.so: announces the one synthetic device when OpenNI
// initialises, opens it by URI, and reports its "unplugging" through OpenNI's device-disconnected event.
#include <cstring>
#include <memory>
#include <mutex>
#include <string>

#include "synth_device.hpp"

namespace facescan::oni_synth {
namespace {

void copyString(char* dst, const char* src) {
    std::strncpy(dst, src, ONI_MAX_STR - 1);
    dst[ONI_MAX_STR - 1] = '\0';
}

}  // namespace

class SynthDriver final : public oni::driver::DriverBase {
 public:
    explicit SynthDriver(OniDriverServices* services) : DriverBase(services) {
        copyString(info_.uri, kSynthUri);
        copyString(info_.vendor, kSynthVendor);
        copyString(info_.name, kSynthName);
        // USB ids of the Kinect v1 camera, so tools that look at them see a Kinect-class device.
        info_.usbVendorId = 0x045e;
        info_.usbProductId = 0x02ae;
    }

    OniStatus initialize(oni::driver::DeviceConnectedCallback connected,
                         oni::driver::DeviceDisconnectedCallback disconnected,
                         oni::driver::DeviceStateChangedCallback state_changed, void* cookie) override {
        const OniStatus rc = DriverBase::initialize(connected, disconnected, state_changed, cookie);
        if (rc != ONI_STATUS_OK) return rc;
        deviceConnected(&info_);  // always present, like a camera that is plugged in
        return ONI_STATUS_OK;
    }

    oni::driver::DeviceBase* deviceOpen(const char* uri, const char* /*mode*/) override {
        if (uri == nullptr || std::strcmp(uri, kSynthUri) != 0) return nullptr;
        std::lock_guard<std::mutex> lock(mutex_);
        if (open_ != nullptr) {
            getServices().errorLoggerAppend("facescan synthetic device is already open");
            return nullptr;
        }
        std::string error;
        const SynthConfig config = SynthConfig::fromEnvironment(&error);
        if (!error.empty()) {
            getServices().errorLoggerAppend("facescan synthetic device: %s", error.c_str());
            return nullptr;
        }
        try {
            open_ = new SynthDevice(config, [this] { deviceDisconnected(&info_); });
        } catch (const std::exception& e) {
            getServices().errorLoggerAppend("facescan synthetic device: %s", e.what());
            return nullptr;
        }
        return open_;
    }

    void deviceClose(oni::driver::DeviceBase* device) override {
        SynthDevice* closing = nullptr;
        {
            std::lock_guard<std::mutex> lock(mutex_);
            if (device == nullptr || device != open_) return;
            closing = open_;
            open_ = nullptr;
        }
        delete closing;  // joins the producer thread, outside our lock
    }

    OniStatus tryDevice(const char* uri) override {
        return (uri != nullptr && std::strcmp(uri, kSynthUri) == 0) ? ONI_STATUS_OK : ONI_STATUS_ERROR;
    }

    // Depth and colour of one render carry the same frameIndex, which is what OpenNI's frame sync matches on;
    // the driver itself has nothing to configure, but must return a non-null group for OpenNI to enable sync.
    void* enableFrameSync(oni::driver::StreamBase** streams, int count) override {
        if (streams == nullptr || count < 1) return nullptr;
        return new int(count);
    }
    void disableFrameSync(void* group) override { delete static_cast<int*>(group); }

    void shutdown() override {
        SynthDevice* closing = nullptr;
        {
            std::lock_guard<std::mutex> lock(mutex_);
            closing = open_;
            open_ = nullptr;
        }
        delete closing;
    }

 private:
    OniDeviceInfo info_{};
    std::mutex mutex_;
    SynthDevice* open_ = nullptr;  // owned; OpenNI hands it back to deviceClose
};

}  // namespace facescan::oni_synth

// The C entry points OpenNI looks up in every library of its driver folder (oniDriverCreate, ...).
ONI_EXPORT_DRIVER(facescan::oni_synth::SynthDriver)
