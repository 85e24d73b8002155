"""Report primitives: headline numbers (results.py), figures (PNG, non-interactive matplotlib),
tables, the HTML report and filming (video.py), below the domain code that uses them; and, above
it, the commands that show runs (motorlab.kinds.media: video, compare; motorlab.kinds.report: report, plot)."""
