// Preloaded into ThreadSanitizer runs (tests/tsan/run.sh): oneTBB on the calling thread only. TBB's
// scheduler (libtbb.so) is not instrumented, so the hand-over of a parallel_for's results from its
// workers looks like a race; with one thread the std::threads' own synchronisation is what is checked.
#include <tbb/global_control.h>

static tbb::global_control one_thread(tbb::global_control::max_allowed_parallelism, 1);
