"""Tests of facette.cli (a package: its test files share names with other subpackages' tests)."""
