"""Layer 6: driving a real arm: serial links, controller drivers, paced streaming with a safe stop."""
