// Compiled into every program in a ThreadSanitizer build (see CMakeLists.txt). TSan only sees
// synchronisation done in instrumented code; Debian's libraries are not instrumented, so a few
// correct patterns in them are reported as races. Each line names the library or function and
// why; nothing in slamd's own code is suppressed.
//
// - cv::Mat::deallocate: cv::Mat counts references with an atomic inside libopencv_core. When
//   two threads share a buffer (the tracking thread keeps the frame's gray image in its feature
//   set while the vanishing-point thread reads the same frame), whichever drops the last
//   reference frees it. The atomic orders that free after the other thread's reads, but TSan
//   cannot see it and reports the free as racing with those reads.
// - libOpenNI2 unlocks a mutex it never locked while it loads (before main), and its internal
//   threads and the DummyDevice driver's unjoined frame thread are reported too.
// - CHOLMOD (the pose graph's factorisation) runs parallel loops with OpenMP: libgomp's worker
//   threads write the workspace the calling thread set up, ordered by libgomp's own barriers,
//   which TSan does not see. Reported as races between the two inside libcholmod and libgomp.

extern "C" const char* __tsan_default_suppressions() {
  return "race:cv::Mat::deallocate\n"
         "mutex:libOpenNI2.so\n"
         "race:libOpenNI2.so\n"
         "thread:libDummyDevice.so\n"
         "race:libcholmod.so\n"
         "race:libgomp.so\n";
}
