// Copyright 2026 The tactfunc Authors.
//
// Guards for text that comes from files users hand to tactfunc: bounded JSON nesting
// (checked before parsing, so no reader or error message recurses without limit),
// UTF-8 validity, and short excerpts of offending values for error messages (a bad
// value is quoted, never dumped whole).
#ifndef TACTFUNC_MODELS_CORE_TEXT_LIMITS_H_
#define TACTFUNC_MODELS_CORE_TEXT_LIMITS_H_

#include <cstddef>
#include <string>
#include <string_view>

namespace tactfunc {

// The deepest JSON nesting ([ and {) any tactfunc reader accepts. tactfunc's own files
// nest at most 4 deep; 64 leaves room for users' "meta" objects.
inline constexpr int kMaxJsonDepth = 64;

// The longest excerpt of an offending value quoted in an error message, in bytes.
inline constexpr std::size_t kMaxQuotedBytes = 200;

// The maximum nesting depth of the brackets of JSON `text` ('[' and '{' outside
// strings), scanning no further than needed to exceed `limit`: returns a value
// > limit as soon as the text nests deeper. Malformed text is left to the parser.
int JsonNestingDepth(std::string_view text, int limit = kMaxJsonDepth);

// True if `text` is well-formed UTF-8 (no overlong forms, surrogates or code points
// above U+10FFFF).
bool IsValidUtf8(std::string_view text);

// `text` itself if it has at most `max_bytes` bytes; else its first bytes (cut at a
// UTF-8 character boundary) followed by "... (N bytes)".
std::string Excerpt(std::string_view text, std::size_t max_bytes = kMaxQuotedBytes);

// Excerpt with bytes that are not printable ASCII written as \xNN, for quoting text
// that may hold control characters or invalid UTF-8.
std::string EscapedExcerpt(std::string_view text, std::size_t max_bytes = kMaxQuotedBytes);

}  // namespace tactfunc

#endif  // TACTFUNC_MODELS_CORE_TEXT_LIMITS_H_
