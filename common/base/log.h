#pragma once
// Logging: the level is tested before anything is formatted; each line says the component.
// One process-wide sink (stderr by default); tests may capture it.

#include <cstdarg>
#include <string>

namespace raystack {

enum class LogLevel { kDebug = 0, kInfo = 1, kWarning = 2, kError = 3, kSilent = 4 };

// Lines below this level are dropped before formatting.
LogLevel GetLogLevel();
void SetLogLevel(LogLevel level);

// Formats and writes one line: "[raystack WARN component] message". Thread-safe.
void LogLine(LogLevel level, const char* component, const char* format, ...)
    __attribute__((format(printf, 3, 4)));

// printf into a std::string, for building error messages.
std::string StrFormat(const char* format, ...) __attribute__((format(printf, 1, 2)));

}  // namespace raystack

#define RAYSTACK_LOG(level, component, ...)                         \
  do {                                                              \
    if ((level) >= ::raystack::GetLogLevel())                       \
      ::raystack::LogLine((level), (component), __VA_ARGS__);       \
  } while (0)
#define LOG_DEBUG(component, ...) RAYSTACK_LOG(::raystack::LogLevel::kDebug, component, __VA_ARGS__)
#define LOG_INFO(component, ...) RAYSTACK_LOG(::raystack::LogLevel::kInfo, component, __VA_ARGS__)
#define LOG_WARNING(component, ...) \
  RAYSTACK_LOG(::raystack::LogLevel::kWarning, component, __VA_ARGS__)
#define LOG_ERROR(component, ...) RAYSTACK_LOG(::raystack::LogLevel::kError, component, __VA_ARGS__)
