// Suppressions built into the ThreadSanitizer test binaries of tests/server.
//
// Debian's Abseil is not instrumented: an absl::Status shared between threads (a failed batch's
// status copied into every request's answer) is freed after an atomic decrement TSan cannot see,
// which it reports as a race with the thread that last wrote the status. The reference count is
// correct (Abseil's own TSan builds pass); the report is a false positive of mixing instrumented
// and uninstrumented code.
extern "C" const char* __tsan_default_suppressions() {
  return "race:absl::*Status::Unref\n";  // also matches UnrefNonInlined
}
