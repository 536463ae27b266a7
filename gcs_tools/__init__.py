"""Ground tools: CLI, in-process flights, SITL launcher, replay, telemetry tools, evaluation."""
