"""Bad input at every stage boundary: a clear message naming the file and the fix, nothing on disk changed."""
