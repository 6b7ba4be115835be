"""Built-in commands; each module is imported only when its command runs."""
