// Copyright 2026 The tactfunc Authors.
//
// The one source of the object library that builds the test suites' precompiled header
// (tests/CMakeLists.txt, TACTFUNC_PCH); it defines nothing.
