// Compiled into every program that links slamd::capture in a ThreadSanitizer build with OpenNI2
// (see CMakeLists.txt). Debian's libOpenNI2 unlocks a mutex it never locked while it loads
// (before main), which TSan reports as "unlock of an unlocked mutex" and which would fail every
// such program; its internal threads and the DummyDevice driver's unjoined frame thread are
// reported too. Only reports inside those two libraries are suppressed.

extern "C" const char* __tsan_default_suppressions() {
  return "mutex:libOpenNI2.so\n"
         "race:libOpenNI2.so\n"
         "thread:libDummyDevice.so\n";
}
