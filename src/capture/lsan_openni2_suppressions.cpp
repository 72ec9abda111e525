// Compiled into every program that links slamd::capture in an AddressSanitizer build with
// OpenNI2 (see CMakeLists.txt). Debian's libOpenNI2 and its device drivers (PS1080, PSLink,
// DummyDevice, OniFile) keep allocations they never free after OpenNI::shutdown(), which
// LeakSanitizer reports at exit and which would fail every program that opened a device or an
// .oni file. Only leaks allocated inside those libraries are suppressed; slamd's own are not.

extern "C" const char* __lsan_default_suppressions() {
  return "leak:libOpenNI2.so\n"
         "leak:libPS1080.so\n"
         "leak:libPSLink.so\n"
         "leak:libDummyDevice.so\n"
         "leak:libOniFile.so\n";
}
