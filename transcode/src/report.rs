//! The run report: report.json and a self-contained report.html.
