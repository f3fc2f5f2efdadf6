// A DDS reader that nothing takes from any more while a writer may still write to it: a session's frame reader once
// the session is given up or finished, its agent streaming on (to a new owner, or until it sees the end).
//
// It must not be deleted then. Cyclone 0.10 delivers a sample to a full keep-all reader by retrying on its receive
// thread, awake all along, for as long as the reader stays full; the process hears nothing meanwhile. Deleting the
// reader waits for Cyclone's garbage collector, which waits for every awake thread to move on: with the reader full
// and nobody taking from it, for ever (the chaos soaks' retiring thread hung there until the watchdog ended the
// server). So such a reader lingers, drained by a thread that never deletes anything (the server's intake), until
// no writer is matched, and only then is it deleted (on the retiring thread). A deletion that waits must never
// hold up the draining of another lingering reader: that one would fill, and the deletion would never end.
#pragma once

#include <dds/dds.h>

namespace facescan::service {

// Takes and drops what `reader` holds. True once no writer is matched (or the reader is gone): nothing can be
// delivered to it any more, and deleting it cannot wait on a full history.
bool drainedAndUnwritten(dds_entity_t reader);

}  // namespace facescan::service
