import { defineConfig } from 'vite';
import react from '@vitejs/plugin-react';

// The anywidget module: one self-contained static/widget.js (CSS inlined), built after the page.
export default defineConfig({
  plugins: [react()],
  define: { 'process.env.NODE_ENV': '"production"' },
  build: {
    outDir: '../static',
    emptyOutDir: false,
    sourcemap: false,
    chunkSizeWarningLimit: 4000,
    lib: { entry: 'src/widget.tsx', formats: ['es'], fileName: () => 'widget.js' },
    minify: true,
    rollupOptions: { output: { codeSplitting: false } },
  },
});
