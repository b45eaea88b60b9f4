// Keeps exid_test_support non-empty.
