// Test library without the exid entry point: must be refused.
extern "C" __attribute__((visibility("default"))) int some_other_function() { return 42; }
