#include "service/lingering_reader.hpp"

namespace facescan::service {

bool drainedAndUnwritten(dds_entity_t reader) {
    constexpr int kBatch = 16;
    void* samples[kBatch];
    dds_sample_info_t infos[kBatch];
    for (;;) {
        samples[0] = nullptr;  // loaned samples
        const dds_return_t n = dds_take(reader, samples, infos, kBatch, kBatch);
        if (n <= 0) break;
        (void)dds_return_loan(reader, samples, n);
        if (n < kBatch) break;
    }
    dds_subscription_matched_status_t matched{};
    return dds_get_subscription_matched_status(reader, &matched) != DDS_RETCODE_OK || matched.current_count == 0;
}

}  // namespace facescan::service
