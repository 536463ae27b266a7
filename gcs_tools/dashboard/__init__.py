"""Live web dashboard (aiohttp + Server-Sent Events + hand-written canvas plots, no CDN)."""
